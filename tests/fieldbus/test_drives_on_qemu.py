# SPDX-License-Identifier: MIT
"""End to end on the real QEMU (no mock of it): the guest side is our
QEMU's CAN0 driven over qtest (fieldbus_qemu.Board), linked by the
can-host-lockstep backend to

- servoamp-drivesim with two CiA 402 drives (an ACTIVE client),
- two `python -m can.logger -i servoamp` processes writing ASC and BLF
  (passive clients),
- this test's own passive canlink client, which sees every frame on the bus.

The guest brings the drives up as a CANopen master would (boot-up, NMT
start, SDO 0x6060 = 8, the 402 enable sequence over RPDO + SYNC), moves the
targets and sees TPDO1 positions follow, then the injected faults come with
EMCY and their codes at the guest times given. The loggers' files hold
every frame; every frame's bus time is its frame_bits at 1 Mbit/s, back to
back when the bus is busy.
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

from fieldbus_helpers import emcy, nmt, rpdo1, sdo_download, sdo_response, sdo_upload, tpdo1
from fieldbus_qemu import Board, GuestFrame, qemu_binary
from servoamp import canlink
from servoamp.drivesim import cia402
from servoamp.drivesim.cia402 import State

pytestmark = pytest.mark.board

REPO = Path(__file__).resolve().parents[2]
MS = 1_000_000
BIT_NS = 1000                      # 1 Mbit/s
NODES = (1, 2)
FE_NODE, FE_AT_S = 2, 0.150        # node 2's load jams: following error trip
OC_NODE, OC_AT_S = 1, 0.200        # node 1: over-current


class Observer:
    """A passive canlink client recording every FRAME (guest frames and, as
    INFO, the answers) in a thread."""

    def __init__(self, path: Path) -> None:
        self.link = canlink.Link.connect(str(path), active=False, name="observer")
        self.records: list[canlink.Record] = []
        self.bye = threading.Event()
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        try:
            while True:
                rec = self.link.recv(None)
                if rec is None or rec.type == canlink.BYE:
                    self.bye.set()
                    return
                self.records.append(rec)
        except BaseException as exc:       # noqa: BLE001 - reported by the test
            self.error = exc
            self.bye.set()


def start_logger(sock: Path, out: Path, workdir: Path) -> subprocess.Popen[str]:
    proc = subprocess.Popen([sys.executable, "-m", "can.logger", "-i", "servoamp", "-c", str(sock),
                             "-f", str(out)], stdout=subprocess.PIPE,
                            stderr=open(workdir / f"{out.name}.err", "w"), text=True, cwd=REPO,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})
    assert proc.stdout is not None
    line = proc.stdout.readline()          # "Connected to ServoampBus: ..." once HELLO came back
    assert "Connected to" in line, line
    return proc


@pytest.fixture
def rig(tmp_path: Path):  # type: ignore[no-untyped-def]
    binary = qemu_binary()
    board = Board(binary, tmp_path)
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


def cycle(board: Board, t_ns: int, frames: list[tuple[int, bytes]]) -> list[GuestFrame]:
    """At guest time ``t_ns``: the guest sends ``frames`` back to back, then
    guest time runs 1 ms; the frames CAN0 received meanwhile."""
    board.clock_set(t_ns)
    for can_id, data in frames:
        board.send(GuestFrame(can_id, data))
    board.clock_set(t_ns + MS)
    return board.receive_all()


def test_master_enables_drives_moves_them_and_sees_their_faults(rig, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    board, procs = rig
    observer = Observer(board.can_sock)
    assert observer.link.bitrate == 1_000_000
    asc, blf = tmp_path / "bus.asc", tmp_path / "bus.blf"
    procs.append(start_logger(board.can_sock, asc, tmp_path))
    procs.append(start_logger(board.can_sock, blf, tmp_path))
    board.can_init()
    drivesim_err = open(tmp_path / "drivesim.err", "w")
    procs.append(subprocess.Popen(
        [sys.executable, "-m", "servoamp.drivesim", "--socket", str(board.can_sock),
         "--nodes", ",".join(map(str, NODES)), "-v",
         "--fault", f"{FE_NODE}:following-error@{FE_AT_S}", "--fault", f"{OC_NODE}:over-current@{OC_AT_S}"],
        stderr=drivesim_err, text=True, cwd=REPO))

    # boot-up: sent by the drives on connecting (outside an exchange)
    seen: list[GuestFrame] = []
    deadline = time.monotonic() + 30
    while {f.can_id for f in seen} < {0x700 + n for n in NODES}:
        assert time.monotonic() < deadline, f"no boot-up: {seen}; {(tmp_path / 'drivesim.err').read_text()}"
        time.sleep(0.02)
        board.clock_step(100_000)
        seen += board.receive_all()
    assert all(f.data == b"\x00" for f in seen if f.can_id in (0x701, 0x702))

    t = (board.now // MS + 1) * MS
    # NMT start all; SDO: modes of operation = CSP, read back, heartbeat 20 ms
    got = cycle(board, t, [nmt(0x01, 0)])
    t += MS
    for n in NODES:
        got = cycle(board, t, [sdo_download(n, 0x6060, 0, 8, 1)])
        t += MS
        assert [sdo_response(f.data) for f in got if f.can_id == 0x580 + n] == [("download-ok", 0x6060, 0, 0)]
        got = cycle(board, t, [sdo_upload(n, 0x6061, 0)])
        t += MS
        assert [sdo_response(f.data) for f in got if f.can_id == 0x580 + n] == [("upload", 0x6061, 0, 8)]
        for index, value, size in ((0x1017, 20, 2), (0x6065, 500, 4)):   # heartbeat 20 ms, FE window
            got = cycle(board, t, [sdo_download(n, index, 0, value, size)])
            t += MS
            assert [sdo_response(f.data)[0] for f in got if f.can_id == 0x580 + n] == ["download-ok"]

    # cyclic: RPDO1 per drive, then SYNC; TPDO1s come back after the SYNC
    status: dict[int, int] = {}
    position: dict[int, int] = {}
    emcys: dict[int, list[tuple[int, int, int]]] = {n: [] for n in NODES}
    heartbeats: dict[int, list[int]] = {n: [] for n in NODES}
    target = {n: 0 for n in NODES}
    followed: dict[int, list[tuple[int, int, int]]] = {n: [] for n in NODES}
    k = 0
    while t < 0.260e9:
        if k < 3:
            cw = (0x06, 0x07, 0x0F)[k]
        else:
            cw = 0x0F
            for n in NODES:      # speed up to 30 * n counts/ms over 40 ms
                target[n] += 30 * n * min(k - 3, 40) // 40
        got = cycle(board, t, [rpdo1(n, cw, target[n]) for n in NODES] + [(0x080, b"")])
        for f in got:
            n = f.can_id & 0x7F
            if f.can_id - n == 0x180:
                status[n], position[n] = tpdo1(f.data)
                followed[n].append((t, target[n], position[n]))
            elif f.can_id - n == 0x80:
                code, reg = emcy(f.data)
                emcys[n].append((t, code, reg))
            elif f.can_id - n == 0x700:
                heartbeats[n].append(f.data[0])
        if k == 5:
            assert all(cia402.state_of(status[n]) == State.OPERATION_ENABLED for n in NODES), status
        k += 1
        t += MS

    # positions followed the targets while enabled, before the faults
    for n in NODES:
        until = (FE_AT_S if n == FE_NODE else OC_AT_S) * 1e9
        moving = [(tg, pos) for tc, tg, pos in followed[n] if tc < until]
        assert moving[-1][0] > 3000 * n and moving[-1][1] > 3000 * n
        # TPDO1's position is sampled at the SYNC, before the target sent with it
        assert all(abs(tg - pos) < 100 * n for tg, pos in moving), moving
    # the faults: EMCY with the code, at the guest time injected (within the
    # following-error timeout and a few cycles for the jam)
    assert [(c, r) for _, c, r in emcys[FE_NODE]] == [(0x8611, 0x21)], emcys
    assert FE_AT_S * 1e9 < emcys[FE_NODE][0][0] < FE_AT_S * 1e9 + 30 * MS
    assert [(c, r) for _, c, r in emcys[OC_NODE]] == [(0x2310, 0x03)], emcys
    assert OC_AT_S * 1e9 - MS <= emcys[OC_NODE][0][0] <= OC_AT_S * 1e9 + MS
    assert all(cia402.state_of(status[n]) == State.FAULT for n in NODES), status
    for n in NODES:
        assert heartbeats[n] and set(heartbeats[n]) == {0x05}, heartbeats
        got = cycle(board, t, [sdo_upload(n, 0x603F, 0)])
        t += MS
        assert [sdo_response(f.data)[3] for f in got if f.can_id == 0x580 + n] == \
               [0x8611 if n == FE_NODE else 0x2310]

    assert board.close() == 0
    assert observer.bye.wait(20) and observer.error is None, observer.error
    for p in procs:
        p.wait(timeout=30)
    assert procs[2].returncode == 0, (tmp_path / "drivesim.err").read_text()

    records = observer.records
    check_bus_times(records)
    # the loggers hold every frame on the bus, in order, at the same times
    for path in (asc, blf):
        reader = can.ASCReader(str(path)) if path.suffix == ".asc" else can.BLFReader(str(path))
        logged = list(reader)
        assert [(m.arbitration_id, bytes(m.data)) for m in logged] == \
               [(r.can_id, r.data) for r in records], path
        t0 = records[0].t_ns / 1e9
        m0 = logged[0].timestamp
        for m, r in zip(logged, records):
            assert abs((m.timestamp - m0) - (r.t_ns / 1e9 - t0)) < 2e-6, (path, m, r)


def check_bus_times(records: list[canlink.Record]) -> None:
    """One frame on the bus at a time, each as long as frame_bits says, in
    guest time order (a client reads an answer after the guest frames sent
    meanwhile, so not in that order): no frame starts before the one before
    it ended; an answer (INFO) to a guest frame starts exactly when the bus
    got free, to the nanosecond; a guest frame starts when the bus got free
    or at the guest time the test wrote it (a multiple of 100 us here)."""
    prev_end = None
    back_to_back = 0
    first_guest = min(r.t_ns for r in records if not r.info)
    for r in sorted(records, key=lambda r: r.t_ns):
        bits = canlink.frame_bits(r.can_id, r.eff, r.rtr, r.dlc, r.data)
        start = r.t_ns - bits * BIT_NS
        if prev_end is not None:
            assert start >= prev_end, f"{r} overlaps the frame before (ended {prev_end})"
            if r.info and r.t_ns > first_guest:
                assert start == prev_end, f"answer {r} not back to back ({start - prev_end} ns gap)"
            elif not r.info:
                assert start == prev_end or start % 100_000 == 0, f"{r} starts at {start}"
            back_to_back += start == prev_end
        prev_end = r.t_ns
    assert back_to_back > len(records) // 2, back_to_back
