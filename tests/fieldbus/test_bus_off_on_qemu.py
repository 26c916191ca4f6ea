# SPDX-License-Identifier: MIT
"""Bus errors and bus off on the emulated bus, end to end on our QEMU
(docs/canlink.md "Bus errors", docs/fieldbus.md "Bus off"): CAN0 of
xilinx-zynq-a9 under qtest (tests/fieldbus/fieldbus_qemu.py), the drive
simulator (servoamp-drivesim, the active client) with a bus short asked for
on its control socket, python-can's logger (an active client through the
``servoamp`` interface) and a passive canlink observer.

- Before the short a SYNC goes out once: TEC 0, error active.
- During the short every attempt of the next SYNC is destroyed: CAN0
  retransmits at once, each attempt starting after the previous one's
  error frame; TEC climbs by 8 and the 32nd error takes it past 255: bus
  off (SR.ESTAT 3, ISR.BSOFF, ISR.ERROR, ESR.BERR, no TXOK).
- Every client gets ERROR for each attempt, the passive observer never the
  FRAME of a destroyed frame; the logger (a listener: held like an active
  client, whole frames only) writes 32 error frames and none of the frames
  destroyed.
- Off the bus nothing is sent; a reset clears the counters, and after the
  short the next SYNC goes out at once (TEC 0, error active) and the drive
  answers again.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import can
import pytest

from fieldbus_qemu import (CAN0, ISR_TXOK, R_ICR, R_ISR, R_MSR, R_SR, R_SRR, R_TXDLC, R_TXDW1,
                           R_TXDW2, R_TXID, SR_NORMAL, SRR_CEN, Board, GuestFrame, idr, qemu_binary)
from servoamp import canlink
from test_drives_on_qemu import Observer, start_logger

pytestmark = pytest.mark.board

REPO = Path(__file__).resolve().parents[2]
MS = 1_000_000
BIT_NS = 1000                      # 1 Mbit/s
R_ECR, R_ESR = 0x10, 0x14
SRR_SRST = 1 << 0
SR_ERRWRN = 1 << 6
ESR_BERR = 1 << 3
ISR_ERROR, ISR_BSOFF = 1 << 8, 1 << 9
NODE = 1
SHORT_MS = 5


def estat(sr: int) -> int:
    return (sr >> 7) & 3


def store(board: Board, can_id: int, data: bytes = b"") -> None:
    """A frame into CAN0's TX FIFO (sent on the write of DW2), without
    expecting TXOK."""
    raw = data.ljust(8, b"\0")
    board.writel(CAN0 + R_TXID, idr(can_id, False, False))
    board.writel(CAN0 + R_TXDLC, len(data) << 28)
    board.writel(CAN0 + R_TXDW1, int.from_bytes(raw[:4], "big"))
    board.writel(CAN0 + R_TXDW2, int.from_bytes(raw[4:], "big"))


@pytest.fixture
def rig(tmp_path: Path):  # type: ignore[no-untyped-def]
    board = Board(qemu_binary(), tmp_path)
    procs: list[subprocess.Popen[str]] = []
    try:
        yield board, procs
    finally:
        board.close()
        for p in procs:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.send_signal(signal.SIGINT)
                p.wait(timeout=10)


def test_a_bus_short_takes_the_controller_bus_off_and_a_reset_brings_it_back(  # type: ignore[no-untyped-def]
        rig, tmp_path: Path) -> None:
    board, procs = rig
    observer = Observer(board.can_sock)
    asc = tmp_path / "bus.asc"
    # a listener: held like an active client, only whole frames (as netboard starts it)
    procs.append(start_logger(board.can_sock, asc, tmp_path, "listen_only=true"))
    board.can_init()
    ctl = tmp_path / "drives.ctl"
    err = tmp_path / "drivesim.err"
    procs.append(subprocess.Popen(
        [sys.executable, "-m", "servoamp.drivesim", "--socket", str(board.can_sock),
         "--nodes", str(NODE), "--control", str(ctl), "-v"],
        stderr=open(err, "w"), text=True, cwd=REPO, env={**os.environ, "PYTHONUNBUFFERED": "1"}))
    deadline = time.monotonic() + 120
    while "connected:" not in err.read_text() or not ctl.exists():
        assert procs[-1].poll() is None and time.monotonic() < deadline, err.read_text()
        time.sleep(0.05)
    # the boot-up (sent on connecting, outside an exchange)
    boot: list[GuestFrame] = []
    while not boot:
        assert board.now < 50 * MS, err.read_text()
        time.sleep(0.02)
        board.clock_step(100_000)
        boot = [f for f in board.receive_all() if f.can_id == 0x700 + NODE]
    sync_bits = canlink.frame_bits(0x080, False, False, 0, b"")

    # before the short: a SYNC goes out, no error
    board.clock_set(10 * MS)
    board.send(GuestFrame(0x080, b""))
    assert board.readl(CAN0 + R_ECR) == 0
    assert estat(board.readl(CAN0 + R_SR)) == 1

    # the short, from the next frame: every attempt destroyed, bus off. The
    # simulator reads its control socket when a frame comes: the request is
    # written first, the frame sent, then the answer read
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as req:
        req.settimeout(30)
        req.connect(str(ctl))
        req.sendall(f"bus-short {SHORT_MS}\n".encode())
        board.clock_set(20 * MS)
        store(board, 0x080)
        assert req.makefile().readline().strip() == f"ok bus-short {SHORT_MS}"
    assert board.readl(CAN0 + R_ECR) == 255            # REC 0, TEC saturated
    sr = board.readl(CAN0 + R_SR)
    assert sr == SR_NORMAL | SR_ERRWRN | 3 << 7, hex(sr)
    isr = board.readl(CAN0 + R_ISR)
    assert isr & (ISR_ERROR | ISR_BSOFF | ISR_TXOK) == ISR_ERROR | ISR_BSOFF, hex(isr)
    assert board.readl(CAN0 + R_ESR) == ESR_BERR
    board.writel(CAN0 + R_ICR, ISR_ERROR | ISR_BSOFF)

    # off the bus: a frame stored is not sent, nothing is received
    store(board, 0x080)
    board.clock_set(40 * MS)
    assert board.receive_all() == []

    # a reset (the firmware's restart): counters cleared, error active;
    # the short is over: the next SYNC goes out, TEC stays 0
    board.writel(CAN0 + R_SRR, SRR_SRST)
    assert board.readl(CAN0 + R_ECR) == 0
    board.writel(CAN0 + R_MSR, 0)
    board.writel(CAN0 + R_SRR, SRR_CEN)
    assert board.readl(CAN0 + R_SR) == SR_NORMAL | 1 << 7
    board.clock_set(41 * MS)
    board.send(GuestFrame(0x080, b""))
    assert board.readl(CAN0 + R_ECR) == 0
    # and the drive answers again: NMT start, then its heartbeat producer
    # (0x1017) is off by default, so ask for its state with an SDO upload
    board.send(GuestFrame(0x600 + NODE, bytes([0x40, 0x41, 0x60, 0, 0, 0, 0, 0])))
    board.clock_set(42 * MS)
    assert [f.can_id for f in board.receive_all()] == [0x580 + NODE]

    assert board.close() == 0
    assert observer.bye.wait(20) and observer.error is None, observer.error
    # the simulator ends cleanly on QEMU's BYE (the logger ends on it too,
    # with python-can's error for a bus that went away)
    assert procs[1].wait(timeout=30) == 0, err.read_text()
    procs[0].wait(timeout=30)
    assert "bus shorted from" in err.read_text(), err.read_text()

    # the attempts as the passive observer saw them: 32 ERRORs, back to
    # back (each attempt after the previous error frame), no FRAME of them;
    # the SYNC before the short and the two frames after the reset as FRAMEs
    errors = [r for r in observer.records if r.type == canlink.ERROR]
    assert len(errors) == 32, errors
    t_start = errors[0].t_ns - (sync_bits + canlink.ERROR_BITS) * BIT_NS
    assert t_start == 20 * MS
    for k, r in enumerate(errors):
        assert r.can_id == 0x080 and r.dlc == 0
        assert r.t_ns == t_start + (k + 1) * (sync_bits + canlink.ERROR_BITS) * BIT_NS, (k, r)
        assert r.seq == errors[0].seq + k
    guest = [r for r in observer.records if r.type == canlink.FRAME and not r.info]
    assert [(r.seq, r.can_id) for r in guest] == [
        (errors[0].seq - 1, 0x080), (errors[-1].seq + 1, 0x080), (errors[-1].seq + 2, 0x600 + NODE)], guest

    # the logger (python-can, through the servoamp interface) wrote them as
    # error frames at the same guest times
    logged = list(can.ASCReader(str(asc)))
    err_frames = [m for m in logged if m.is_error_frame]
    assert len(err_frames) == 32
    syncs = [m for m in logged if m.arbitration_id == 0x080 and not m.is_error_frame]
    assert len(syncs) == 2, syncs        # the one before the short, the one after
    t0 = next(m.timestamp for m in logged if not m.is_error_frame) - observer.records[0].t_ns / 1e9
    for m, r in zip(err_frames, errors):
        assert abs(m.timestamp - t0 - r.t_ns / 1e9) < 2e-6, (m, r)
