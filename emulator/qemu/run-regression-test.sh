#!/usr/bin/env bash
# Run one of our qtests against a QEMU: the Cadence TTC regression qtest
# (patches/0002, tests/qtest/cadence-ttc-test.c) by default, or with
# --test zynq-can-test the CAN controllers' (patches/0008,
# tests/qtest/zynq-can-test.c), or with --test can-lockstep-test the
# canlink backend's (patches/0010, tests/qtest/can-lockstep-test.c), or with
# --test xlnx-zynqmp-rpu-test the ZynqMP RPU's (patches/0014-0023,
# tests/qtest/xlnx-zynqmp-rpu-test.c), or with --test
# xlnx-zcu102-pl-timer-test the ZCU102's timer in the PL (patches/0027,
# tests/qtest/xlnx-zcu102-pl-timer-test.c), or with --test xlnx-can-test
# upstream's qtest of the ZynqMP's CAN controllers (its status checks
# adjusted by patches/0011); all on qemu-system-aarch64, the one emulator
# of both boards (patches/0026 registers the Zynq-7000 tests for it).
# Exits 0 when it passes, 1 when it fails,
# 124 when it times out (the unpatched TTC model livelocks in clock_step, so
# a hang is the expected failure there).
#
#   emulator/qemu/run-regression-test.sh                  # the cached build (build.sh --print)
#   emulator/qemu/run-regression-test.sh DIR              # an install dir (bin/, libexec/servoamp/)
#                                                         # or a QEMU build dir (SERVOAMP_QEMU_KEEP_BUILD=1)
#   emulator/qemu/run-regression-test.sh DIR --qemu BIN   # DIR's test binary against another
#                                                         # QEMU, e.g. Debian's unpatched
#                                                         # /usr/bin/qemu-system-aarch64 (same 10.0.2)
#   emulator/qemu/run-regression-test.sh [DIR] --test zynq-can-test
#   emulator/qemu/run-regression-test.sh [DIR] --test can-lockstep-test
#   emulator/qemu/run-regression-test.sh [DIR] --test xlnx-zynqmp-rpu-test
#   emulator/qemu/run-regression-test.sh [DIR] --test xlnx-zcu102-pl-timer-test
#   emulator/qemu/run-regression-test.sh [DIR] --test xlnx-can-test
#
# Environment: SERVOAMP_QEMU_TEST_TIMEOUT (seconds without progress, default
# 60: the test is killed when its output (a TAP line per case) has not grown
# for that long, however long the whole run takes on a loaded host; the TTC
# test takes about 2 s on a fixed QEMU, can-lockstep-test about 20 s).
set -euo pipefail

here=$(cd "$(dirname "$0")" && pwd)
log() { printf '[qemu-test] %s\n' "$*" >&2; }
die() { printf '[qemu-test] error: %s\n' "$*" >&2; exit 2; }

dir="" qemu="" test=cadence-ttc-test
while [ $# -gt 0 ]; do
	case $1 in
	--qemu) qemu=${2:?--qemu needs a path}; shift 2 ;;
	--test) test=${2:?--test needs a name}; shift 2 ;;
	-h | --help) sed -n '2,31p' "$0"; exit 0 ;;
	*) [ -z "$dir" ] || die "one directory only"; dir=$1; shift ;;
	esac
done
[ -n "$dir" ] || dir=$("$here/build.sh" --print)
dir=$(cd "$dir" && pwd)

test_bin=""
case $test in
*/* | "") die "--test takes a qtest's name (cadence-ttc-test, zynq-can-test, can-lockstep-test, xlnx-zynqmp-rpu-test, xlnx-zcu102-pl-timer-test, xlnx-can-test)" ;;
esac
# the emulator every qtest runs on (both boards' machines are in it)
emu=qemu-system-aarch64
for t in "$dir/libexec/servoamp/$test" "$dir/tests/qtest/$test"; do
	[ -x "$t" ] && { test_bin=$t; break; }
done
[ -n "$test_bin" ] || die "no $test in $dir (libexec/servoamp/ or tests/qtest/)"
if [ -z "$qemu" ]; then
	for q in "$dir/bin/$emu" "$dir/$emu"; do
		[ -x "$q" ] && { qemu=$q; break; }
	done
fi
[ -n "$qemu" ] && [ -x "$qemu" ] || die "no $emu in $dir (give one with --qemu)"

limit=${SERVOAMP_QEMU_TEST_TIMEOUT:-60}
out=$(mktemp)
trap 'rm -f "$out"' EXIT
log "$test_bin against $qemu ($("$qemu" --version | head -1)), timeout $limit s without progress"

# Own process group, so that a livelocked QEMU (which no longer serves
# SIGTERM) is killed together with the test on timeout.
t0=$(date +%s)
QTEST_QEMU_BINARY=$qemu setsid "$test_bin" --tap -k >"$out" 2>&1 &
pid=$!
rc="" size=0 last=$t0
while [ -z "$rc" ]; do
	now=$(date +%s) grown=$(stat -c %s "$out")
	if [ "$grown" != "$size" ]; then
		size=$grown last=$now	# progress: a case started or ended
	fi
	if ! kill -0 "$pid" 2>/dev/null; then
		set +e; wait "$pid"; rc=$?; set -e
	elif [ $((now - last)) -ge "$limit" ]; then
		kill -KILL -- "-$pid" 2>/dev/null || true
		wait "$pid" 2>/dev/null || true
		rc=124
	else
		sleep 0.2
	fi
done
cat "$out"
secs=$(($(date +%s) - t0))
case $rc in
0) log "PASS ($secs s)" ;;
124) log "FAIL: no progress for $limit s (livelock?), $secs s in all; the test and its QEMU were killed"; exit 124 ;;
*) log "FAIL: exit status $rc ($secs s)"; exit 1 ;;
esac
