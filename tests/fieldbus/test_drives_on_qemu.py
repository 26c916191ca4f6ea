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
EMCY and their codes at the guest times given, and a third drive drops off
the bus (no TPDO, heartbeat or SDO answer after). The loggers' files hold
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
from dataclasses import dataclass
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
NODES = (1, 2, 3)
FE_NODE, FE_AT_S = 2, 0.200        # node 2's load jams: following error trip
OC_NODE, OC_AT_S = 1, 0.250        # node 1: over-current
OFF_NODE, OFF_AT_S = 3, 0.120      # node 3 drops off the bus
RAMP = {1: 30, 2: 60, 3: 0}        # top speed, counts/ms
T0 = 50 * MS                       # the master starts (after the boot-ups)
T_END = 310 * MS


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


def start_logger(sock: Path, out: Path, workdir: Path, *bus_kwargs: str) -> subprocess.Popen[str]:
    """python-can's logger on the bus (``bus_kwargs``: its --bus-kwargs,
    e.g. listen_only=true), once connected."""
    extra = ["--bus-kwargs", *bus_kwargs] if bus_kwargs else []
    proc = subprocess.Popen([sys.executable, "-m", "can.logger", "-i", "servoamp", "-c", str(sock),
                             "-f", str(out), *extra], stdout=subprocess.PIPE,
                            stderr=open(workdir / f"{out.name}.err", "w"), text=True, cwd=REPO,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})
    assert proc.stdout is not None
    line = proc.stdout.readline()          # "Connected to ServoampBus: ..." once HELLO came back
    assert "Connected to" in line, line
    if "listen_only=true" in bus_kwargs:
        assert "listen-only" in line, line
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


@dataclass
class Run:
    records: list[canlink.Record]
    status: dict[int, int]
    emcys: dict[int, list[tuple[int, int, int]]]
    heartbeats: dict[int, list[tuple[int, int]]]
    followed: dict[int, list[tuple[int, int, int]]]
    tpdo_times: dict[int, list[int]]
    error_codes: dict[int, int | None]


def scenario(board: Board, tmp_path: Path, procs: list[subprocess.Popen[str]],
             loggers: list[Path]) -> Run:
    """The master's side, from the drives' boot-up to their faults."""
    observer = Observer(board.can_sock)
    assert observer.link.bitrate == 1_000_000
    for path in loggers:
        procs.append(start_logger(board.can_sock, path, tmp_path))
    board.can_init()
    faults = [f"{FE_NODE}:following-error@{FE_AT_S}", f"{OC_NODE}:over-current@{OC_AT_S}",
              f"{OFF_NODE}:off-bus@{OFF_AT_S}"]
    procs.append(subprocess.Popen(
        [sys.executable, "-m", "servoamp.drivesim", "--socket", str(board.can_sock),
         "--nodes", ",".join(map(str, NODES)), "-v"] + [a for f in faults for a in ("--fault", f)],
        stderr=open(tmp_path / "drivesim.err", "w"), text=True, cwd=REPO))
    drivesim = procs[-1]

    # boot-up: sent by the drives on connecting, outside an exchange, so at
    # a host-dependent guest time; all that follows starts at T0. Guest time
    # stands until the simulator is connected (its start is slow on a busy host)
    err = tmp_path / "drivesim.err"
    deadline = time.monotonic() + 120
    while "connected:" not in err.read_text():
        assert drivesim.poll() is None and time.monotonic() < deadline, err.read_text()
        time.sleep(0.05)
    seen: list[GuestFrame] = []
    while {f.can_id for f in seen} < {0x700 + n for n in NODES}:
        assert board.now < T0 - MS, f"no boot-up: {seen}; {err.read_text()}"
        time.sleep(0.02)
        board.clock_step(100_000)
        seen += board.receive_all()
    assert all(f.data == b"\x00" for f in seen if f.can_id - 0x700 in NODES)

    t = T0
    # NMT start all; SDO: modes of operation = CSP (read back), heartbeat
    # 20 ms (its phase from here on), following error window 500
    got = cycle(board, t, [nmt(0x01, 0)])
    t += MS
    for n in NODES:
        got = cycle(board, t, [sdo_download(n, 0x6060, 0, 8, 1)])
        t += MS
        assert [sdo_response(f.data) for f in got if f.can_id == 0x580 + n] == [("download-ok", 0x6060, 0, 0)]
        got = cycle(board, t, [sdo_upload(n, 0x6061, 0)])
        t += MS
        assert [sdo_response(f.data) for f in got if f.can_id == 0x580 + n] == [("upload", 0x6061, 0, 8)]
        for index, value, size in ((0x1017, 20, 2), (0x6065, 500, 4)):
            got = cycle(board, t, [sdo_download(n, index, 0, value, size)])
            t += MS
            assert [sdo_response(f.data)[0] for f in got if f.can_id == 0x580 + n] == ["download-ok"]

    # cyclic: RPDO1 per drive, then SYNC; TPDO1s come back after the SYNC
    run = Run([], {}, {n: [] for n in NODES}, {n: [] for n in NODES}, {n: [] for n in NODES},
              {n: [] for n in NODES}, {})
    target = {n: 0 for n in NODES}
    k = 0
    while t < T_END:
        if k < 3:
            cw = (0x06, 0x07, 0x0F)[k]
        else:
            cw = 0x0F
            for n in NODES:      # speed up to RAMP[n] counts/ms over 40 ms
                target[n] += RAMP[n] * min(k - 3, 40) // 40
        got = cycle(board, t, [rpdo1(n, cw, target[n]) for n in NODES] + [(0x080, b"")])
        for f in got:
            n = f.can_id & 0x7F
            if f.can_id - n == 0x180:
                run.status[n], pos = tpdo1(f.data)
                run.followed[n].append((t, target[n], pos))
                run.tpdo_times[n].append(t)
            elif f.can_id - n == 0x80:
                code, reg = emcy(f.data)
                run.emcys[n].append((t, code, reg))
            elif f.can_id - n == 0x700:
                run.heartbeats[n].append((t, f.data[0]))
        if k == 5:
            assert all(cia402.state_of(run.status[n]) == State.OPERATION_ENABLED for n in NODES), run.status
        k += 1
        t += MS
    for n in NODES:
        got = cycle(board, t, [sdo_upload(n, 0x603F, 0)])
        t += MS
        answers = [sdo_response(f.data)[3] for f in got if f.can_id == 0x580 + n]
        run.error_codes[n] = answers[0] if answers else None

    assert board.close() == 0
    assert observer.bye.wait(20) and observer.error is None, observer.error
    assert drivesim.wait(timeout=30) == 0, (tmp_path / "drivesim.err").read_text()
    run.records = observer.records
    return run


def test_master_enables_drives_moves_them_and_sees_their_faults(rig, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    board, procs = rig
    asc, blf = tmp_path / "bus.asc", tmp_path / "bus.blf"
    run = scenario(board, tmp_path, procs, [asc, blf])

    # positions followed the targets while enabled, up to the faults
    for n in (FE_NODE, OC_NODE):
        until = (FE_AT_S if n == FE_NODE else OC_AT_S) * 1e9
        moving = [(tg, pos) for tc, tg, pos in run.followed[n] if tc < until]
        assert moving[-1][0] > 3000 * n and moving[-1][1] > 3000 * n
        # TPDO1's position is sampled at the SYNC, before the target sent with it
        assert all(abs(tg - pos) < 100 * n for tg, pos in moving), moving
    # the faults: EMCY with the code, at the guest time injected (the jam
    # trips once the following error passed 500 counts for 5 ms)
    assert [(c, r) for _, c, r in run.emcys[FE_NODE]] == [(0x8611, 0x21)], run.emcys
    assert FE_AT_S * 1e9 < run.emcys[FE_NODE][0][0] < FE_AT_S * 1e9 + 30 * MS
    assert [(c, r) for _, c, r in run.emcys[OC_NODE]] == [(0x2310, 0x03)], run.emcys
    assert OC_AT_S * 1e9 - MS <= run.emcys[OC_NODE][0][0] <= OC_AT_S * 1e9 + MS
    for n in (FE_NODE, OC_NODE):
        assert cia402.state_of(run.status[n]) == State.FAULT, run.status
        assert run.error_codes[n] == (0x8611 if n == FE_NODE else 0x2310)
        assert {s for _, s in run.heartbeats[n]} == {0x05}, run.heartbeats
        hb = [tc for tc, _ in run.heartbeats[n]]
        assert all(19 * MS <= b - a <= 21 * MS for a, b in zip(hb, hb[1:])), hb
    # the drive off the bus: TPDOs and heartbeats until then, nothing after
    assert run.tpdo_times[OFF_NODE] and max(run.tpdo_times[OFF_NODE]) < OFF_AT_S * 1e9
    assert min(run.tpdo_times[OFF_NODE]) < OFF_AT_S * 1e9 - 20 * MS
    assert all(tc < OFF_AT_S * 1e9 for tc, _ in run.heartbeats[OFF_NODE])
    assert run.error_codes[OFF_NODE] is None and run.emcys[OFF_NODE] == []

    for p in procs:
        p.wait(timeout=30)
    check_bus_times(run.records)
    # the loggers hold every frame on the bus, in order, at the same times
    for path in (asc, blf):
        reader = can.ASCReader(str(path)) if path.suffix == ".asc" else can.BLFReader(str(path))
        logged = list(reader)
        assert [(m.arbitration_id, bytes(m.data)) for m in logged] == \
               [(r.can_id, r.data) for r in run.records], path
        t0 = run.records[0].t_ns / 1e9
        m0 = logged[0].timestamp
        for m, r in zip(logged, run.records):
            assert abs((m.timestamp - m0) - (r.t_ns / 1e9 - t0)) < 2e-6, (path, m, r)


def test_two_runs_put_the_same_frames_on_the_bus_at_the_same_guest_times(tmp_path: Path) -> None:
    """Guest time stays deterministic: everything after the boot-ups (which
    come at host-dependent times, sent outside an exchange) is the same, to
    the bit and the nanosecond, in two runs."""
    binary = qemu_binary()
    runs = []
    for i in range(2):
        work = tmp_path / f"run{i}"
        work.mkdir()
        board = Board(binary, work)
        procs: list[subprocess.Popen[str]] = []
        try:
            runs.append(scenario(board, work, procs, []))
        finally:
            board.close()
            for p in procs:
                if p.poll() is None:
                    p.kill()
                p.wait()
    a, b = ([(r.can_id, r.flags, r.dlc, r.data, r.t_ns) for r in run.records if r.t_ns > T0] for run in runs)
    assert len(a) > 1000
    assert a == b


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
