#!/usr/bin/env bash
# The main job: install what is needed, build everything that is missing
# (kernel from cache, remoteproc module, initramfs, servo firmware), boot the
# emulated Zynq-7000 in QEMU, start servod, load and start the servo
# firmware through the remoteproc sysfs, show the cycle running (trace log,
# ampctl status/stats, parameters, a hang and its recovery), stop it and
# shut down cleanly; then run the squares-and-circles G-code program
# through the motion pipeline on four CiA 402 drives over CAN (two per bus,
# simulated on the host in lockstep; the bus load is printed, the frames
# logged into build/demo/can0.asc and can1.asc) while streaming every cycle through
# `servoamp bridge`: live on the ws:// address it prints (Foxglove: Open
# connection > Foxglove WebSocket) and into an MCAP file through the Foxglove
# SDK, with plots (build/demo/run.mcap, build/demo/plots/).
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
cd "$here"
scripts/bootstrap.sh
.venv/bin/python scripts/west_commands/emu.py --accel tcg,thread=single --script scripts/demo/guest-commands.sh "$@"
exec scripts/demo/record.sh --program --can
