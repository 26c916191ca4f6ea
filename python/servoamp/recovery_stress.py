"""Recovery stress: many hang-and-recover rounds of the servo firmware in one
boot of the emulated board, with console input arriving at varied moments.

Each round: ``ampctl debug hang`` (the firmware stops its heartbeat), then,
after a random host delay, a random short command typed on the console
while servod's watchdog reports the stall and remoteproc stops, reloads and
restarts the firmware; the round passes when servod logs the recovery and
the parameter set restored (a count that must grow by exactly one per
round) within a guest-time budget, and the console answers.

A round whose console stops answering is a *hang*: the launcher dumps both
vCPUs' registers (PC and LR symbolised against vmlinux, servod and the
firmware) and the GIC into ``vcpu-state.txt`` next to the UART logs, which
are kept; the board is then restarted and the rounds go on, so that the
result is a rate (hangs per round).

Options make the guest busy (a CPU hog in the guest's shell, beside servod)
and the host busy (one spinning process per host core), the conditions of
issue 20's failing demo run.

    python -m servoamp.recovery_stress [--board NAME] [--rounds N] [--guest-load] [--host-load] [--seed S] [--json FILE]

Any board (boards/NAME, default zynq7000_qemu): the servo core's
remoteproc is found as servod finds it (:data:`servoamp.netboard.FIND_RPROC`).

tests/robot/test_recovery_stress.py runs a short stress in the test suite;
docs/reliability.md has the rates of long runs.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import random
import re
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from servoamp import netboard, qemu

SERVOD_LOG = "/tmp/servod.log"
ROUND_GUEST_S = 5.0            # guest seconds a round may take to recover
CONSOLE_TIMEOUT_S = 90.0       # host seconds without an answer = a hang

# commands typed while a recovery runs: short, some reading the remoteproc
# sysfs (the guest's $R: the servo core's remoteproc, set at the start)
# and servod, some only printing
TYPED = (
    "true",
    "echo x",
    "cat $R/state",
    "ampctl status >/dev/null 2>&1",
    "sleep 0.01",
    "dmesg | tail -n 1 >/dev/null",
    "cat $R/state $R/recovery",
)


@dataclass
class Result:
    rounds: int = 0
    passed: int = 0
    hangs: int = 0
    slow: int = 0                        # recovered, but not within ROUND_GUEST_S
    lost: int = 0                        # back, without the exchange or the parameter
    mode: str = "hang"
    boots: int = 0
    kept_logs: list[str] = field(default_factory=list)
    hang_rounds: list[int] = field(default_factory=list)
    detectors: list[str] = field(default_factory=list)   # kernel stall reports seen
    guest_load: bool = False
    host_load: bool = False
    seconds: float = 0.0

    @property
    def rate(self) -> float:
        return self.hangs / self.rounds if self.rounds else 0.0


def _spin() -> None:
    while True:
        pass


def host_load(n: int | None = None) -> list[multiprocessing.Process]:
    """One busy process per host core (or n)."""
    procs = []
    for _ in range(n or multiprocessing.cpu_count()):
        p = multiprocessing.Process(target=_spin, daemon=True)
        p.start()
        procs.append(p)
    return procs


class Board:
    """One boot: servod and the firmware running, console helpers."""

    def __init__(self, board: qemu.Board, images: qemu.Images, guest_load: bool, keep_logs: bool,
                 console_timeout: float = CONSOLE_TIMEOUT_S) -> None:
        self.m = qemu.QemuMachine(board, images, accel="tcg,thread=single", keep_logs=keep_logs)
        self.prompt = str(board.data["linux"]["prompt"])
        self.rproc = ""                 # found after the boot
        self.guest_load = guest_load
        self.console_timeout = console_timeout

    def sh(self, cmd: str, timeout: float | None = None) -> tuple[int, str]:
        return qemu.run_shell(self.m.uart(0), cmd, self.prompt, timeout=timeout or self.console_timeout)

    def count(self, text: str) -> int:
        _, out = self.sh(f'grep -c "{text}" {SERVOD_LOG}')
        last = out.strip().splitlines()[-1] if out.strip() else "0"
        return int(last) if last.isdigit() else 0

    def start(self) -> None:
        self.m.start()
        qemu.boot_to_shell(self.m, timeout=max(self.console_timeout, 60.0))
        # --recovery-limit 0: rounds restart the firmware more than 3 times a
        # minute on purpose, which would latch servod's fault (docs/cycle.md)
        self.sh(f"(servod --recovery-limit 0 > {SERVOD_LOG} 2>&1 &)")
        self.sh(f"while ! grep -q 'waiting for the servo' {SERVOD_LOG}; do sleep 0.05; done")
        self.rproc = netboard.find_rproc(lambda c: self.sh(c)[1])
        self.sh(f"R={self.rproc}")
        self.sh(f"echo rpu_app.elf > {self.rproc}/firmware; echo start > {self.rproc}/state")
        self.sh(f"while ! grep -q 'parameter set loaded' {SERVOD_LOG}; do sleep 0.05; done")
        if self.guest_load:
            # a CPU hog beside servod, at normal priority, for the whole boot
            self.sh("(while :; do :; done > /dev/null 2>&1 &)")

    def round(self, rng: random.Random, done_before: int, mode: str, n: int) -> str:
        """One hang and its recovery (mode "hang"), or one stop and start
        through the remoteproc sysfs (mode "stopstart"): 'ok', 'slow',
        'lost' (back, but the parameter or the exchange is not), or raises
        QemuError (the console stopped answering)."""
        kp = 50 + n % 100                 # a value this round sets, restored after
        self.sh(f"ampctl param set pos_kp {kp} > /dev/null 2>&1")
        if mode == "hang":
            self.sh("ampctl debug hang > /dev/null 2>&1")
        else:
            self.sh(f"echo stop > {self.rproc}/state; echo start > {self.rproc}/state")
        # console input at a varied moment of the detection and recovery
        time.sleep(rng.uniform(0.0, 0.4))
        for _ in range(rng.randint(1, 3)):
            self.sh(rng.choice(TYPED))
            time.sleep(rng.uniform(0.0, 0.1))
        tries = int(ROUND_GUEST_S / 0.02)
        _, out = self.sh(
            f'i=0; while [ "$(grep -c "parameter set loaded" {SERVOD_LOG})" -le {done_before} ] && '
            f'[ $i -lt {tries} ]; do sleep 0.02; i=$((i+1)); done; '
            f'grep -c "parameter set loaded" {SERVOD_LOG}')
        got = int(out.strip().splitlines()[-1])
        if got != done_before + 1:
            return "slow"
        # the exchange is back and the parameter restored
        _, out = self.sh("ampctl stats | grep '^linux.exchanges='; sleep 0.05; "
                         "ampctl stats | grep '^linux.exchanges='; ampctl param get pos_kp")
        # by pattern, not by line: the kernel may print on the console meanwhile
        ex = [int(x) for x in re.findall(r"^linux\.exchanges=(\d+)$", out, re.M)]
        got_kp = re.findall(r"^pos_kp=([-+0-9.eE]+)", out, re.M)
        try:
            back = len(ex) == 2 and ex[1] > ex[0] and len(got_kp) == 1 and float(got_kp[0]) == kp
        except ValueError:
            back = False
        if not back:
            print(f"[stress] round {n}: recovered but not back: {out!r}", flush=True)
        return "ok" if back else "lost"

    def detectors(self) -> list[str]:
        out = "".join(u.output for u in self.m.uarts[:1])
        pats = r"(soft lockup|rcu_sched self-detected stall|rcu: INFO|blocked for more than|BUG: workqueue lockup|hung_task)"
        return sorted({m.group(1) for m in re.finditer(pats, out)})

    def stop(self) -> None:
        self.m.stop()


def run(rounds: int, seed: int, guest_load: bool, with_host_load: bool, keep_logs: bool = False,
        max_boots: int = 20, mode: str = "hang", console_timeout: float = CONSOLE_TIMEOUT_S,
        board: qemu.Board | None = None, images: qemu.Images | None = None) -> Result:
    board = board or qemu.Board.load("zynq7000_qemu")
    images = images or qemu.prepare_images(board)
    rng = random.Random(seed)
    res = Result(guest_load=guest_load, host_load=with_host_load, mode=mode)
    hogs = host_load() if with_host_load else []
    t0 = time.monotonic()
    try:
        while res.rounds < rounds and res.boots < max_boots:
            b = Board(board, images, guest_load, keep_logs, console_timeout)
            res.boots += 1
            try:
                b.start()
                done = b.count("parameter set loaded")
                while res.rounds < rounds:
                    res.rounds += 1
                    try:
                        what = b.round(rng, done, mode, res.rounds)
                    except qemu.QemuError as e:
                        res.hangs += 1
                        res.hang_rounds.append(res.rounds)
                        b.m.mark_failed()
                        print(f"[stress] round {res.rounds}: HANG: {str(e).splitlines()[0]}", flush=True)
                        break
                    if what == "ok":
                        res.passed += 1
                        done += 1
                    elif what == "lost":
                        res.lost += 1
                        done += 1
                    else:
                        res.slow += 1
                        done = b.count("parameter set loaded")
                        print(f"[stress] round {res.rounds}: not recovered within {ROUND_GUEST_S} guest s", flush=True)
                    if res.rounds % 25 == 0:
                        print(f"[stress] {res.rounds}/{rounds} rounds, {res.hangs} hangs, {res.slow} slow, "
                              f"{time.monotonic() - t0:.0f} s", flush=True)
                res.detectors = sorted(set(res.detectors) | set(b.detectors()))
            finally:
                if b.m.run_dir is not None and (b.m._failed or keep_logs):
                    res.kept_logs.append(str(b.m.run_dir))
                b.stop()
    finally:
        for p in hogs:
            p.terminate()
    res.seconds = time.monotonic() - t0
    return res


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--board", default="zynq7000_qemu", help="boards/NAME (default %(default)s)")
    ap.add_argument("--rounds", type=int, default=200)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--guest-load", action="store_true", help="a CPU hog in the guest beside servod")
    ap.add_argument("--host-load", action="store_true", help="one spinning process per host core")
    ap.add_argument("--mode", choices=("hang", "stopstart"), default="hang",
                    help="hang: ampctl debug hang and remoteproc's recovery; stopstart: stop and start through sysfs")
    ap.add_argument("--keep-logs", action="store_true")
    ap.add_argument("--console-timeout", type=float, default=CONSOLE_TIMEOUT_S,
                    help="host seconds without an answer that count as a hang (default %(default)s)")
    ap.add_argument("--max-boots", type=int, default=20, help="give up after this many boots (hangs restart the board)")
    ap.add_argument("--json", type=Path)
    a = ap.parse_args(argv)
    res = run(a.rounds, a.seed, a.guest_load, a.host_load, a.keep_logs, max_boots=a.max_boots, mode=a.mode,
              console_timeout=a.console_timeout, board=qemu.Board.load(a.board))
    d = asdict(res) | {"rate": res.rate}
    print(f"[stress] {res.mode}: {res.rounds} rounds in {res.boots} boot(s): {res.passed} back, {res.slow} slow, "
          f"{res.lost} lost, "
          f"{res.hangs} hangs (rate {res.rate:.4f}); guest load {res.guest_load}, host load {res.host_load}; "
          f"{res.seconds:.0f} s")
    for k in res.kept_logs:
        print(f"[stress] logs: {k}")
    if res.detectors:
        print(f"[stress] kernel detectors fired: {', '.join(res.detectors)}")
    if a.json:
        a.json.write_text(json.dumps(d, indent=2) + "\n")
    return 0 if res.hangs == res.slow == res.lost == 0 and res.rounds >= a.rounds else 1


if __name__ == "__main__":
    sys.exit(main())
