#!/usr/bin/env bash
# servoamp's benchmarks behind one entry point: installs what they need
# (scripts/bootstrap.sh: host tools only, the emulated board too when a
# board benchmark is selected), runs them, writes bench/results/<name>.json
# and prints one table of every figure against its target
# (bench/targets.toml). bench/README.md says what each benchmark measures
# and how long it takes.
#
#   scripts/bench.sh                    # all of them (about 9 min, 8 QEMU boots)
#   scripts/bench.sh transport motion   # some of them
#   scripts/bench.sh --list             # names, host/board, duration, command
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

# fieldbus (issue 22, bench/fieldbus/can_bench.py, boots QEMU with the drive
# simulator): run here when named or when all run, before the others;
# servoamp.bench then shows its bench/results/fieldbus.json in the table
# like any results file (python/servoamp/bench.py has no entry for it yet).
fb=0 names=0 quick=0 info=0 verbose=0 results="" prev=""
for a in "$@"; do
	if [ "$prev" = --results ]; then results=$a prev=""; continue; fi
	case $a in
	--list|--table|--scope|-h|--help) info=1 ;;
	--quick) quick=1 ;;
	-v|--verbose) verbose=1 ;;
	--results) prev=--results ;;
	--results=*) results=${a#--results=} ;;
	-*) ;;
	fieldbus) fb=1 names=1 ;;
	*) names=1 ;;
	esac
done
[ "$names" = 1 ] || fb=1
rc=0
if [ "$info" = 0 ] && [ "$fb" = 1 ]; then
	scripts/bootstrap.sh >&2
	if [ "$quick" = 1 ]; then dir=${results:-build/bench/quick} qa=(--quick) log=build/bench/fieldbus-quick.log
	else dir=${results:-bench/results} qa=() log=build/bench/fieldbus.log; fi
	mkdir -p "$dir" build/bench
	echo "[bench] fieldbus: running (about 3 min, 4 QEMU boots)"
	t0=$SECONDS
	cmd=(.venv/bin/python bench/fieldbus/can_bench.py "${qa[@]}" --json "$dir/fieldbus.json")
	echo "\$ ${cmd[*]}" > "$log"
	if [ "$verbose" = 1 ]; then "${cmd[@]}" 2>&1 | tee -a "$log"; frc=${PIPESTATUS[0]}
	else "${cmd[@]}" >> "$log" 2>&1 && frc=0 || frc=$?; fi
	if [ "$frc" = 0 ]; then echo "[bench] fieldbus: $((SECONDS - t0)) s, wrote $dir/fieldbus.json"
	else echo "[bench] fieldbus: failed (exit $frc) after $((SECONDS - t0)) s: see $log"; rc=1; fi
fi
.venv/bin/python -m servoamp.bench "$@" || rc=1
exit $rc
