# SPDX-License-Identifier: MIT
"""The steps of issue 33 in the CAN board test (test_can_board.py, one
boot): a second NMT master on can0 and a slow fault reset on can1. They
record what they see in the module's ``out``; the test module asserts."""

from __future__ import annotations

import contextlib
import threading
import time
from pathlib import Path
from typing import Any, Iterator

import can

from servoamp import canload, netboard

RESET_AXIS, RESET_BUS, RESET_NODE = 3, 1, 2   # the drive whose fault reset is slow
RESET_CYCLES = 30                      # SYNCs it needs to leave Fault (drive simulator)
RESET_TIMEOUT_MS = 100                 # the master's fault reset time (axis_can.c)


def _enabled(st: dict[str, str], axes: int) -> bool:
    return all(st.get(f"axis{i}.drive") == "operation-enabled" for i in range(axes))


@contextlib.contextmanager
def _other_master(sock: Path) -> Iterator[can.BusABC]:
    """A second NMT master on the bus: a passive python-can client of the
    `servoamp` interface (QEMU never waits for it), read in a thread so
    that its socket never fills while the test waits."""
    bus = can.Bus(interface="servoamp", channel=str(sock))
    stop = threading.Event()

    def drain() -> None:
        while not stop.is_set():
            try:
                bus.recv(0.2)
            except can.CanOperationError:
                return

    th = threading.Thread(target=drain, daemon=True)
    th.start()
    try:
        yield bus
    finally:
        stop.set()
        th.join(timeout=5)
        bus.shutdown()


def _nmt(cs: int, node: int) -> can.Message:
    return can.Message(arbitration_id=0x000, data=[cs, node], is_extended_id=False)


def second_master(cb: netboard.ControllerBoard, out: dict[str, Any], program: str, axes: int) -> None:
    """A passive python-can client of can0 sends NMT 'enter pre-operational'
    to node 1 (axis 0) while the program runs, then 'stop' to node 2
    (axis 1); one resume brings both back."""
    cb.sh_rc(f"ampctl run {program} 2>&1", timeout=60)
    out["nmt_prog_run"] = cb.wait_status(lambda st: st.get("program.state") == "running", 120,
                                         "the program to run", raise_on_timeout=False)
    with _other_master(cb.can_socks[0]) as other:
        other.send(_nmt(0x80, 1))
        out["nmt_preop"] = cb.wait_status(
            lambda st: st.get("axis0.error") == "0xff04" and st.get("program.state") != "running", 120,
            "axis0: error 0xff04 (pre-operational), the program ended", raise_on_timeout=False)
        other.send(_nmt(0x02, 2))
        out["nmt_stopped"] = cb.wait_status(lambda st: st.get("axis1.error") == "0xff05", 120,
                                            "axis1: error 0xff05 (stopped)", raise_on_timeout=False)
        if out["nmt_stopped"].get("axis1.error") != "0xff05":
            # not detected (the master before issue 33): the other master
            # starts its drives again, so the steps after this one can run
            other.send(_nmt(0x01, 0))
            cb.sh("sleep 0.2", timeout=120)
    cb.sh("sleep 0.2", timeout=120)
    cb.ampctl("resume", expected_rc=None)                 # once
    out["nmt_enabled"] = cb.wait_status(
        lambda st: _enabled(st, axes) and all(st.get(f"axis{a}.error") == "0x0000" for a in range(axes)), 240,
        "every axis enabled again after one resume", raise_on_timeout=False)


def slow_fault_reset(cb: netboard.ControllerBoard, out: dict[str, Any], axes: int = 4) -> None:
    """Node 2 of can1 (axis 3) trips (over-current); its fault reset is
    first refused, then takes RESET_CYCLES SYNCs; one resume each."""
    ax = RESET_AXIS
    cb.drives(RESET_BUS, f"fault-reset {RESET_NODE} never")
    cb.drives(RESET_BUS, f"fault {RESET_NODE} over-current")
    out["reset_fault"] = cb.wait_status(lambda st: st.get(f"axis{ax}.error") == "0x2310", 120,
                                        f"axis{ax}: error 0x2310", raise_on_timeout=False)
    cb.sh("sleep 0.1", timeout=120)
    cb.ampctl("resume", expected_rc=None)
    out["reset_refused"] = cb.wait_status(lambda st: st.get(f"axis{ax}.error") == "0xff09", 120,
                                          f"axis{ax}: fault reset refused (0xff09)", raise_on_timeout=False)
    cb.drives(RESET_BUS, f"fault-reset {RESET_NODE} {RESET_CYCLES}")
    cb.ampctl("resume", expected_rc=None)                 # once
    out["reset_enabled"] = cb.wait_status(
        lambda st: _enabled(st, axes) and st.get(f"axis{ax}.error") == "0x0000", 240,
        f"axis{ax} enabled after one resume", raise_on_timeout=False)
    cb.drives(RESET_BUS, f"fault-reset {RESET_NODE} 0")
    # a statistics line of the bus from after the second reset
    servo = cb.machine.uart(1) if cb.machine else None
    assert servo is not None
    n = len(canload.master_stats(servo.output, RESET_BUS))
    deadline = time.monotonic() + 120
    while len(canload.master_stats(servo.output, RESET_BUS)) <= n and time.monotonic() < deadline:
        cb.sh("sleep 0.5", timeout=120)
    out["reset_log"] = servo.output
