#!/usr/bin/env bash
# The whole test suite: installs what is needed (scripts/bootstrap.sh), then
# runs every test under tests/ with pytest (host C tests, sanitizers, the
# stress test, the motion pipeline, and the board tests and Robot Framework
# suites on the emulated boards).
#
#   scripts/test.sh [--board NAME]... [-j N] [PYTEST ARGS...]
#
#   --board NAME   the emulated boards whose tests run (boards/NAME; repeat
#                  or separate with commas); default: every board. Host
#                  tests always run (tests/conftest.py says which test is
#                  whose).
#   -j N           N pytest workers (pytest-xdist, --dist loadgroup): host
#                  tests stay in order on one worker, each board test file
#                  and Robot suite is a group of its own, so two QEMUs run
#                  at once (default: SERVOAMP_TEST_JOBS, else 2 on a host
#                  with 2 or more CPUs, else 1). -j 1: one process, no
#                  xdist. The waits on a guest's console and the viewer
#                  tests' waits count the time their processes could run
#                  (python/servoamp/hoststall.py): other load on the cores
#                  lengthens them instead of failing them (README,
#                  docs/status.md).
# Other arguments go to pytest (e.g. tests/amp_lib -k unit: then only the
# paths given run, else all of tests/).
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
cd "$here"
ncpu=$(nproc 2>/dev/null || echo 1)
jobs=${SERVOAMP_TEST_JOBS:-$((ncpu >= 2 ? 2 : 1))}
args=()
while [ $# -gt 0 ]; do
	case $1 in
	--board) [ $# -ge 2 ] || { echo "test.sh: --board wants a board name" >&2; exit 2; }
		args+=(--board "$2"); shift 2 ;;
	--board=*) args+=(--board "${1#--board=}"); shift ;;
	-j) [ $# -ge 2 ] || { echo "test.sh: -j wants a number" >&2; exit 2; }
		jobs=$2; shift 2 ;;
	-j[0-9]*) jobs=${1#-j}; shift ;;
	*) args+=("$1"); shift ;;
	esac
done
case $jobs in
''|*[!0-9]*|0) echo "test.sh: -j $jobs: expected a number of workers, 1 or more" >&2; exit 2 ;;
esac
# tests/ unless the arguments name test paths themselves
paths=(tests)
for a in ${args[@]+"${args[@]}"}; do
	case $a in -*) ;; *) [ -e "${a%%::*}" ] && paths=() ;; esac
done
scripts/bootstrap.sh
if [ "$jobs" -gt 1 ]; then
	args=(-n "$jobs" --dist loadgroup ${args[@]+"${args[@]}"})
fi
exec .venv/bin/python -m pytest ${paths[@]+"${paths[@]}"} ${args[@]+"${args[@]}"}
