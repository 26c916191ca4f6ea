# SPDX-License-Identifier: MIT
"""A host hiccup must not drop the drive simulator (issue 36, item 1;
docs/canlink.md, "The exchange").

Our QEMU under qtest (fieldbus_qemu.Board) with servoamp-drivesim (four
drives, an ACTIVE client) and a host CANopen master that is a passive
canlink client sending SYNC at 1 kHz of host time. The guest sends a frame
every millisecond of guest time (each one an exchange with the simulator).
QEMU is paused for 50 ms (SIGSTOP, SIGCONT) ten times: the master's SYNCs
pile up in its socket, QEMU reads them at once when it runs again, and the
drives answer every one with a TPDO1 (as INFO frames, outside any
exchange). Those answers are not answers to the guest's frame: before the
fix QEMU counted every frame the simulator wrote before its DONE against
the guest frame's limit of 32, dropped it ("too many answers to one
frame") on the first or second pause, and every drive vanished.

A python-can logger (``python -m can.logger -i servoamp``, a passive
client) records the bus meanwhile: its timestamps (each frame's end on the
modelled bus) must never go back (item 5: before the fix a guest frame
reached passive clients at once and an answer only at its bus time, so
frames went back by up to milliseconds in its file).

Pass: the simulator is connected to the end (QEMU logs no disconnect), the
master still sees all four drives answer its SYNCs after the last pause,
when QEMU quits the simulator exits 0 without a traceback, and the
logger's file is in time order.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import can
import pytest

from fieldbus_helpers import nmt
from fieldbus_qemu import Board, GuestFrame, qemu_binary
from servoamp import canlink

pytestmark = pytest.mark.board

REPO = Path(__file__).resolve().parents[2]
MS = 1_000_000
NODES = (1, 2, 3, 4)
PAUSES = 10
PAUSE_S = 0.050


class Master:
    """A passive client: SYNC every millisecond of host time from one
    thread, every record read in another (TPDO1s counted per node, with the
    host time they came)."""

    def __init__(self, path: Path) -> None:
        self.link = canlink.Link.connect(str(path), active=False, name="master")
        self.stop = threading.Event()
        self.tpdos: list[tuple[float, int]] = []
        self.error: BaseException | None = None
        self.sent = 0
        self.threads = [threading.Thread(target=self._sync, daemon=True),
                        threading.Thread(target=self._read, daemon=True)]
        for t in self.threads:
            t.start()

    def _sync(self) -> None:
        nxt = time.monotonic()
        try:
            while not self.stop.is_set():
                self.link.send_frame(0x080)
                self.sent += 1
                nxt += 0.001
                time.sleep(max(0.0, nxt - time.monotonic()))
        except OSError:
            pass

    def _read(self) -> None:
        try:
            while True:
                rec = self.link.recv(None)
                if rec is None or rec.type == canlink.BYE:
                    return
                if rec.type == canlink.FRAME and rec.can_id - 0x180 in NODES:
                    self.tpdos.append((time.monotonic(), rec.can_id - 0x180))
        except BaseException as exc:          # noqa: BLE001 - reported by the test
            self.error = exc

    def close(self) -> None:
        self.stop.set()
        self.threads[0].join(5)


def test_host_pauses_do_not_drop_the_drive_simulator(tmp_path: Path) -> None:
    board = Board(qemu_binary(), tmp_path, timeout_ms=2000)
    err = tmp_path / "drivesim.err"
    drivesim = subprocess.Popen(
        [sys.executable, "-m", "servoamp.drivesim", "--socket", str(board.can_sock),
         "--nodes", ",".join(map(str, NODES)), "-v"],
        stderr=open(err, "w"), text=True, cwd=REPO,
        env={**os.environ, "PYTHONPATH": str(REPO / "python")})
    master = None
    asc = tmp_path / "bus.asc"
    logger = subprocess.Popen([sys.executable, "-m", "can.logger", "-i", "servoamp", "-c", str(board.can_sock),
                               "-f", str(asc)], stdout=subprocess.PIPE, stderr=open(tmp_path / "logger.err", "w"),
                              text=True, cwd=REPO,
                              env={**os.environ, "PYTHONUNBUFFERED": "1", "PYTHONPATH": str(REPO / "python")})
    try:
        assert logger.stdout is not None
        line = logger.stdout.readline()        # "Connected to ServoampBus: ..." once HELLO came back
        assert "Connected to" in line, line
        board.can_init()
        deadline = time.monotonic() + 120
        while "connected:" not in err.read_text():
            assert drivesim.poll() is None and time.monotonic() < deadline, err.read_text()
            time.sleep(0.05)
        # NMT start all: the drives answer every SYNC with TPDO1
        board.clock_step(MS)
        board.send(GuestFrame(*nmt(0x01, 0)))
        board.clock_step(MS)
        board.receive_all()
        master = Master(board.can_sock)

        pauses = 0
        t_next_pause = time.monotonic() + 0.3
        t_last_pause = 0.0
        while pauses < PAUSES or time.monotonic() < t_last_pause + 0.5:
            # the guest: its own frame (a heartbeat, which no drive answers)
            # every millisecond of guest time; what it receives is left in
            # CAN0's RX FIFO (overruns do not matter here)
            board.send(GuestFrame(0x77F, b"\x05"))
            board.clock_step(MS)
            if pauses < PAUSES and time.monotonic() >= t_next_pause:
                os.kill(board.proc.pid, signal.SIGSTOP)
                time.sleep(PAUSE_S)
                os.kill(board.proc.pid, signal.SIGCONT)
                pauses += 1
                t_last_pause = time.monotonic()
                t_next_pause = t_last_pause + 0.2
            assert drivesim.poll() is None, \
                f"the drive simulator exited after {pauses} pauses:\n{err.read_text()}"
        master.close()
        time.sleep(0.2)
        after = {n for t, n in master.tpdos if t > t_last_pause + 0.1}
        assert master.error is None, master.error
        assert master.sent > 500, master.sent
        assert after == set(NODES), f"drives answering SYNC after the last pause: {sorted(after)}"
    finally:
        if master is not None:
            master.close()
        rc = board.close()
        log = (tmp_path / "qemu.log").read_text()
        try:
            drc = drivesim.wait(timeout=30)
        except subprocess.TimeoutExpired:
            drivesim.kill()
            drc = drivesim.wait()
        if master is not None:
            master.link.close()
        try:
            logger.wait(timeout=30)
        except subprocess.TimeoutExpired:
            logger.send_signal(signal.SIGINT)
            logger.wait(timeout=10)
    assert "disconnected" not in log, log
    assert rc == 0, log
    text = err.read_text()
    assert drc == 0 and "Traceback" not in text, text
    stamps = [m.timestamp for m in can.LogReader(str(asc)) if not m.is_error_frame]
    assert len(stamps) > 1000, len(stamps)
    back = [(i, a, b) for i, (a, b) in enumerate(zip(stamps, stamps[1:])) if b < a]
    assert not back, f"{len(back)} of {len(stamps)} frames go back in time, first {back[:3]}"
