#!/usr/bin/env bash
# servoamp's benchmarks behind one entry point: installs what they need
# (scripts/bootstrap.sh: host tools only, the emulated board too when a
# board benchmark is selected), runs them, writes bench/results/<name>.json
# and prints one table of every figure against its target
# (bench/targets.toml). bench/README.md says what each benchmark measures
# and how long it takes.
#
#   scripts/bench.sh                    # all of them on every board (--list: each one's duration)
#   scripts/bench.sh transport motion   # some of them
#   scripts/bench.sh -b zynqmp_qemu     # board benchmarks on that board only (repeatable;
#                                       # default: every board; host ones run once)
#   scripts/bench.sh --list             # names, host/board, on which board, duration, command
#   scripts/bench.sh --table            # only the table of bench/results
#   scripts/bench.sh --quick [NAME...]  # tiny configurations into build/bench/quick
#
# `west bench` runs this script with the same arguments.
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
cd "$here"
SERVOAMP_BOOTSTRAP=host scripts/bootstrap.sh >&2
export PYTHONPATH="$here/python${PYTHONPATH:+:$PYTHONPATH}"
if [ "$(.venv/bin/python -m servoamp.bench --scope "$@")" = all ]; then
	scripts/bootstrap.sh >&2
fi

exec .venv/bin/python -m servoamp.bench "$@"
