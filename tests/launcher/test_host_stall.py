# SPDX-License-Identifier: MIT
"""The console waits count the time the guest could run (servoamp.hoststall):
the time the host held QEMU off its CPUs extends a wait, at most
hoststall.CAP times its timeout, and a wait the host did not hold up ends
on time.

A "QEMU" here is a busy process pinned to one CPU beside three other busy
processes on it (so it runs about a quarter of the time, less on a loaded
host); the "guest" answers on a socket after a while on the host's clock.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from servoamp.board import QemuError
from servoamp.hoststall import CAP, Deadline, StallMeter, thread_waits
from servoamp.uart import Uart

REPO = Path(__file__).resolve().parents[2]
SPIN = "import os, sys; os.sched_setaffinity(0, {int(sys.argv[1])})\nwhile True: pass"


def spinners(n: int) -> Iterator[int]:
    """The pid of a busy process sharing one CPU with n - 1 others."""
    cpu = min(os.sched_getaffinity(0))
    procs = [subprocess.Popen([sys.executable, "-c", SPIN, str(cpu)]) for _ in range(n)]
    try:
        time.sleep(0.3)
        yield procs[0].pid
    finally:
        for p in procs:
            p.kill()
            p.wait()


@pytest.fixture
def crowded() -> Iterator[int]:
    """Runs about a quarter of the time (less on a loaded host)."""
    yield from spinners(4)


@pytest.fixture
def starved() -> Iterator[int]:
    """Runs about a sixteenth of the time: less than 1 / CAP."""
    yield from spinners(16)


def uart_pair(tmp_path: Path, meter: StallMeter | None) -> tuple[Uart, socket.socket]:
    a, b = socket.socketpair()
    return Uart("uart0", a, tmp_path / "uart0.log", stall=meter), b


def answer_after(sock: socket.socket, delay_s: float, line: str) -> threading.Thread:
    def run() -> None:
        time.sleep(delay_s)
        sock.sendall(line.encode())
    t = threading.Thread(target=run, daemon=True)
    t.start()
    return t


def test_the_kernel_counts_run_queue_waits() -> None:
    waits = thread_waits([os.getpid()])
    if waits is None:
        pytest.skip("this kernel keeps no schedstat: the waits use the host's clock alone")
    assert (os.getpid(), threading.get_native_id()) in waits


def test_a_crowded_process_is_held_off(crowded: int) -> None:
    meter = StallMeter(lambda: [crowded])
    t0 = time.monotonic()
    mark = meter.mark()
    if mark is None:
        pytest.skip("no schedstat")
    time.sleep(1.0)
    held, wall = meter.held_s(mark), time.monotonic() - t0
    # its fair share is a quarter of the CPU: held about three quarters
    assert 0.5 * wall < held <= wall + 0.05, (held, wall)


def test_held_time_extends_a_wait(tmp_path: Path, crowded: int) -> None:
    meter = StallMeter(lambda: [crowded])
    if meter.mark() is None:
        pytest.skip("no schedstat")
    uart, guest = uart_pair(tmp_path, meter)
    # 1 s of a quarter CPU ends after about 4 s on the host's clock
    answer_after(guest, 2.0, "ready\n")
    t0 = time.monotonic()
    assert uart.wait_for_line("ready", timeout=1.0) == "ready"
    assert time.monotonic() - t0 >= 1.9


def test_without_a_meter_the_same_wait_fails_on_time(tmp_path: Path, crowded: int) -> None:
    uart, guest = uart_pair(tmp_path, None)
    answer_after(guest, 2.0, "ready\n")
    t0 = time.monotonic()
    with pytest.raises(QemuError, match=r"no line matching 'ready' \(1 s\)"):
        uart.wait_for_line("ready", timeout=1.0)
    assert time.monotonic() - t0 < 1.9


def test_a_wait_the_host_did_not_hold_up_ends_on_time(tmp_path: Path) -> None:
    """A guest that gets its CPU (here: an idle process) and never answers:
    the wait ends after its timeout, with nothing added."""
    idle = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        uart, _guest = uart_pair(tmp_path, StallMeter(lambda: [idle.pid]))
        t0 = time.monotonic()
        with pytest.raises(QemuError, match=r"\(1 s\)"):
            uart.wait_for_line("never", timeout=1.0)
        assert time.monotonic() - t0 < 3.0
    finally:
        idle.kill()
        idle.wait()


def test_the_cap_ends_a_wait_however_long_the_host_holds_off(tmp_path: Path, starved: int) -> None:
    """Held off nearly all the time, a wait of T s ends after CAP * T s in
    all (its T s of running time would take longer), and says how long the
    host held QEMU off."""
    meter = StallMeter(lambda: [starved])
    if meter.mark() is None:
        pytest.skip("no schedstat")
    uart, _guest = uart_pair(tmp_path, meter)
    t0 = time.monotonic()
    with pytest.raises(QemuError, match=r"the host held QEMU off its CPUs"):
        uart.wait_for_line("never", timeout=0.5)
    took = time.monotonic() - t0
    assert CAP * 0.5 - 0.2 < took < CAP * 0.5 + 1.5, took


def test_a_deadline_counts_the_time_its_processes_could_run(crowded: int) -> None:
    """hoststall.Deadline (the viewer tests' waits): held off three quarters
    of the time, 0.5 s of running time take about 2 s."""
    d = Deadline(0.5, StallMeter(lambda: [crowded]))
    t0 = time.monotonic()
    while not d.expired():
        time.sleep(0.05)
    assert time.monotonic() - t0 >= 1.0, d.describe()
    quiet = Deadline(0.5, StallMeter(lambda: [os.getpid()]))
    t0 = time.monotonic()
    while not quiet.expired():
        time.sleep(0.05)
    assert time.monotonic() - t0 < 1.5, quiet.describe()


def test_the_browser_drivers_clock_counts_the_same(tmp_path: Path) -> None:
    """tools/viewer/hoststall.mjs (drive.mjs's timeouts): its process tree's
    hold-offs, here four busy children on one CPU, are what runClock takes
    off the wall time."""
    script = tmp_path / "clock.mjs"
    script.write_text(f"""
import {{ spawn }} from "node:child_process";
import {{ runClock }} from "{REPO / 'tools/viewer/hoststall.mjs'}";
const cpu = {min(os.sched_getaffinity(0))};
const kids = [0, 1, 2, 3].map(() => spawn({sys.executable!r}, ["-c", {SPIN!r}, String(cpu)]));
await new Promise((r) => setTimeout(r, 300));
const clock = runClock();
await new Promise((r) => setTimeout(r, 1000));
console.log(JSON.stringify({{ wall: clock.wall(), held: clock.held(), spent: clock.spent(900) }}));
for (const k of kids) k.kill("SIGKILL");
""")
    res = subprocess.run(["node", str(script)], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    got = json.loads(res.stdout)
    assert got["held"] > 0.5 * got["wall"], got
    assert got["spent"] is False, got   # 900 ms of running time: not yet
