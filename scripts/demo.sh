#!/usr/bin/env bash
# The main job: install what is needed, build everything that is missing
# (kernel from cache, remoteproc module, initramfs, servo firmware), boot the
# emulated board in QEMU (the Zynq-7000 by default, or the ZynqMP), start servod, load and start the servo
# firmware through the remoteproc sysfs, show the cycle running (trace log,
# ampctl status/stats, parameters, a hang and its recovery), stop it and
# shut down cleanly; then run the squares-and-circles G-code program
# through the motion pipeline on four CiA 402 drives over CAN (two per bus,
# simulated on the host in lockstep; the bus load is printed, the frames
# logged into build/demo/can0.asc and can1.asc) while streaming every cycle through
# `servoamp bridge`: live on the ws:// address it prints (Foxglove: Open
# connection > Foxglove WebSocket) and into an MCAP file through the Foxglove
# SDK, with plots (build/demo/run.mcap, build/demo/plots/).
#
#   scripts/demo.sh [--board zynq7000_qemu|zynqmp_qemu] [emu options]
#
# --board (default zynq7000_qemu): the board folder; its board.yaml names
# the first part's guest commands (demo.guest_commands). On zynqmp_qemu the
# servo firmware runs on R5 0 (rpu_app-can.elf on the LPD's two CAN
# controllers in the recording). Other arguments go to west emu.
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
cd "$here"
board=zynq7000_qemu
args=()
while [ $# -gt 0 ]; do
	case $1 in
	--board|-b) [ $# -ge 2 ] || { echo "demo.sh: $1 needs a board" >&2; exit 2; }; board=$2; shift 2 ;;
	--board=*) board=${1#--board=}; shift ;;
	*) args+=("$1"); shift ;;
	esac
done
[ -f "boards/$board/board.yaml" ] || { echo "demo.sh: no board '$board' (boards/*/board.yaml)" >&2; exit 2; }
scripts/bootstrap.sh
guest=$(.venv/bin/python -c 'import sys, yaml; print(yaml.safe_load(open(sys.argv[1]))["demo"]["guest_commands"])' \
	"boards/$board/board.yaml")
servod_args=$(PYTHONPATH=python .venv/bin/python -m servoamp.netboard --servod-args "$board")
.venv/bin/python scripts/west_commands/emu.py -b "$board" --accel tcg,thread=single \
	-c "SERVOD_ARGS='$servod_args'" --script "$guest" ${args[@]+"${args[@]}"}
exec scripts/demo/record.sh --board "$board" --program --can
