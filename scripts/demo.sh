#!/usr/bin/env bash
# The main job: install what is needed, build everything that is missing
# (kernel from cache, remoteproc module, initramfs, servo firmware), boot the
# emulated Zynq-7000 in QEMU, load and start the servo firmware through the
# remoteproc sysfs, show it running (its trace log and heartbeat), stop it
# and shut down cleanly.
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
cd "$here"
scripts/bootstrap.sh
exec .venv/bin/python scripts/west_commands/emu.py --accel tcg,thread=single --script scripts/demo/guest-commands.sh "$@"
