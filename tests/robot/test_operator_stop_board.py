"""An operator's stop is final (issue 33, item 1), on the emulated board, in
one boot: servod with its default recovery bounds (3 restarts within 60 s
latch a fault), then 100 rounds of

    echo start > .../state; wait for `ampctl status` to say link=attached;
    run for a varied time (0 to 300 ms); echo stop > .../state;
    2 s later: remoteproc says "offline", `ampctl param get` exits 3

with no restart and no latch; then, in the same boot, a real hang
(`ampctl debug hang`) is still detected and recovered, with its parameter
set restored.

Before this change the firmware stopped its heartbeat when it saw
remoteproc's STOP and servod's watchdog took that for a stall: it reported
a crash and started the firmware again (rounds 1 to 3 read "running"), and
the fourth stop latched a fault. Now the firmware writes STOPPING in its
state word first, and servod asks remoteproc again before any report
(docs/cycle.md, "An operator's stop"). Times are guest times (virtual
under -icount); the rounds run in batches, one shell command each, so that
the console round trips stay few. The same logic on the host, with both
kinds of stop and a stop during a recovery: tests/servod/test_servod_recovery_stop.c."""

from __future__ import annotations

import random
import re

import pytest

from servoamp import qemu

pytestmark = pytest.mark.board

ROUNDS = 100
BATCH = 10
LOG = "/tmp/servod.log"
RPROC = "/sys/class/remoteproc/remoteproc0"
SE_OFFLINE = 3


# One round, a shell function in the guest (`r N RUN_S`): prints
# `ROUND N STATE RC POLLS`; defined once, so that each batch is a short
# line (the console's line editor cuts long ones).
ROUND_FN = ("r() { echo start > " + RPROC + "/state; i=0; "
            "while ! ampctl status 2>/dev/null | grep -q '^link=attached'; do "
            "sleep 0.02; i=$((i+1)); [ $i -ge 500 ] && break; done; "
            "sleep $2; echo stop > " + RPROC + "/state; sleep 2; "
            "s=$(cat " + RPROC + "/state); ampctl param get pos_kp > /dev/null 2>&1; "
            "echo \"ROUND $1 $s $? $i\"; }")


def test_operator_stop_is_final_100_rounds_then_a_hang_recovered(images: qemu.Images) -> None:
    board = qemu.Board.load("zynq7000_qemu")
    prompt = str(board.data["linux"]["prompt"])
    rng = random.Random(33)
    m = qemu.QemuMachine(board, images)
    m.start()
    try:
        qemu.boot_to_shell(m, timeout=120)
        console = m.uart(0)

        def sh(cmd: str, timeout: float = 60.0) -> tuple[int, str]:
            return qemu.run_shell(console, cmd, prompt, timeout=timeout)

        sh(f"(servod > {LOG} 2>&1 &)")
        sh(f"i=0; while ! grep -q 'waiting for the servo' {LOG} && [ $i -lt 500 ]; do sleep 0.02; "
           f"i=$((i+1)); done")
        sh(f"echo rpu_app.elf > {RPROC}/firmware")
        sh(ROUND_FN)
        rounds: list[tuple[int, str, int, int]] = []
        for first in range(1, ROUNDS + 1, BATCH):
            script = "; ".join(f"r {n} {rng.uniform(0.0, 0.3):.3f}"
                               for n in range(first, min(first + BATCH, ROUNDS + 1)))
            _, out = sh(script, timeout=600)
            got = [(int(a), b, int(c), int(d)) for a, b, c, d in
                   re.findall(r"^ROUND (\d+) (\S+) (\d+) (\d+)$", out, re.M)]
            rounds += got
            bad = [r for r in got if r[1] != "offline" or r[2] != SE_OFFLINE or r[3] >= 500]
            if bad:
                m.mark_failed()
                _, log = sh(f"tail -n 40 {LOG}")
                pytest.fail(f"rounds {bad} (n, state 2 s after the stop, ampctl exit, attach polls); "
                            f"servod's log:\n{log}")
        assert [r[0] for r in rounds] == list(range(1, ROUNDS + 1)), rounds
        _, log = sh(f"cat {LOG}", timeout=120)
        crashes = log.count("reporting a crash")
        latches = log.count("fault latched")
        restarts = log.count("recovery complete")
        stops = log.count("stopped on request")
        print(f"[stop] {len(rounds)} rounds: {stops} stops on request logged, {crashes} crash reports, "
              f"{restarts} restarts, {latches} latches", flush=True)
        assert crashes == 0 and restarts == 0 and latches == 0, log[-4000:]
        # the firmware's own word was seen in (almost) every round; a stop
        # that came before its attach has no word to say (attach polls < 500)
        assert stops >= ROUNDS - 5, log[-4000:]
        rc, out = sh("ampctl fault")
        assert "latched=0" in out and "restarts_in_window=0" in out, out

        # the same boot: a firmware that hangs on its own is still recovered
        sh(f"echo start > {RPROC}/state; i=0; "
           f"while ! ampctl status 2>/dev/null | grep -q '^link=attached'; do sleep 0.02; i=$((i+1)); "
           f"[ $i -ge 500 ] && break; done")
        rc, out = sh("ampctl param set pos_kp 77")
        assert rc == 0, out
        sh("ampctl debug hang > /dev/null 2>&1")
        rc, out = sh(f"i=0; while ! grep -q 'recovery complete' {LOG} && [ $i -lt 1000 ]; do sleep 0.02; "
                     f"i=$((i+1)); done; grep -c 'reporting a crash' {LOG}; ampctl param get pos_kp; "
                     f"cat {RPROC}/state", timeout=120)
        assert re.search(r"^1$", out, re.M), out
        assert re.search(r"^pos_kp=77(\.0+)?\b", out, re.M), out
        assert "running" in out, out
    except BaseException:
        m.mark_failed()
        raise
    finally:
        m.stop()
