#!/usr/bin/env bash
# The board suite N times in a row with the host loaded: one busy process
# per host core (stress-ng --cpu), as on a shared CI machine. A test that
# passes unloaded and fails here depends on host timing: that is a bug
# unless timing is what it tests.
#
#   scripts/test-loaded.sh            # 5 runs of `pytest -m board`
#   scripts/test-loaded.sh 3 -k cycle # 3 runs, extra arguments go to pytest
#
# Prints one line per run (passed/failed counts) and a summary; exits
# non-zero if any run failed. Each run's pytest output is in
# build/test-loaded/run-N.log.
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
cd "$here"
runs=${1:-5}
[ $# -gt 0 ] && shift
case $runs in '' | *[!0-9]*) echo "usage: $0 [RUNS] [pytest args]" >&2; exit 2 ;; esac

scripts/bootstrap.sh
if ! command -v stress-ng >/dev/null; then
	echo "[loaded] installing stress-ng"
	sudo_cmd=""; [ "$(id -u)" -eq 0 ] || sudo_cmd="sudo"
	$sudo_cmd env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends stress-ng \
		>>build/bootstrap.log 2>&1 || { tail -20 build/bootstrap.log; exit 1; }
fi

out=build/test-loaded
mkdir -p "$out"
# the images first, unloaded: a cold kernel build is not what is tested here
.venv/bin/python scripts/west_commands/emu.py --build-only >"$out/images.log" 2>&1 ||
	{ tail -20 "$out/images.log"; exit 1; }

cores=$(nproc)
stress-ng --cpu "$cores" --timeout 0 >/dev/null 2>&1 &
hog=$!
trap 'kill $hog 2>/dev/null || true; wait $hog 2>/dev/null || true' EXIT
echo "[loaded] $cores busy processes (stress-ng pid $hog); $runs runs of pytest -m board $*"

bad=0
for i in $(seq 1 "$runs"); do
	t0=$(date +%s)
	rc=0
	.venv/bin/python -m pytest tests -m board -q -p no:cacheprovider "$@" >"$out/run-$i.log" 2>&1 || rc=$?
	summary=$(grep -E '^[0-9]+ (passed|failed)|^=+ .*(passed|failed)' "$out/run-$i.log" | tail -1 | tr -d '=')
	echo "[loaded] run $i/$runs: ${summary:-no summary} (exit $rc, $(($(date +%s) - t0)) s, log $out/run-$i.log)"
	if [ $rc -ne 0 ]; then
		bad=$((bad + 1))
		grep -E '^(FAILED|ERROR)' "$out/run-$i.log" | sed 's/^/[loaded]   /' || true
	fi
done
echo "[loaded] $((runs - bad)) of $runs runs green"
[ $bad -eq 0 ]
