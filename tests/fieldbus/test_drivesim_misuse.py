# SPDX-License-Identifier: MIT
"""The drive simulator under misuse (issue 36, items 6-10): malformed SDO
requests, invalid PDO mappings, a silent control connection, QEMU
dropping the simulator, the EMCY error register, what the EDS advertises
and the fault reaction; and a fuzz harness (hypothesis) that feeds the
drives random frames and sequences. Host-side: the real Drive, the real
``servoamp-drivesim`` against a canlink peer (fieldbus_helpers.Peer)."""

from __future__ import annotations

import os
import socket
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fieldbus_helpers import (MS, NMT_RESET_COMM, NMT_RESET_NODE, NMT_START, NODE, Bench, Peer, emcy, nmt,
                              rpdo1, sdo_download, sdo_response, sdo_upload, tpdo1)
from servoamp import canlink
from servoamp.canlink import BYE, DONE, FRAME, Record
from servoamp.drivesim import cia402
from servoamp.drivesim.__main__ import Control, control_request
from servoamp.drivesim.cia402 import State
from servoamp.drivesim.drive import Drive, FaultKind, Frame, Injection

TOP = Path(__file__).resolve().parents[2]
ABORT_CS = 0x05040001

# --- item 6: malformed SDO requests ------------------------------------------------


def _abort(b: Bench, request: bytes) -> tuple[int, int, int]:
    kind, index, sub, code = b.sdo((0x600 + b.node, request))
    assert kind == "abort"
    return index, sub, code


@pytest.mark.parametrize("reset", [None, NMT_RESET_NODE, NMT_RESET_COMM])
@pytest.mark.parametrize("request_", [
    bytes([0xE0, 0x00, 0x10, 0x00, 0, 0, 0, 0]),          # ccs 7: no such command
    bytes(8),                                              # ccs 0: a download segment, no download
    bytes([0x60, 0, 0, 0, 0, 0, 0, 0]),                    # ccs 3: an upload segment, no upload
    bytes([0x70, 0, 0, 0, 0, 0, 0, 0]),                    # ccs 3, toggle 1
])
def test_malformed_sdo_first_request_is_aborted(request_: bytes, reset: int | None) -> None:
    """The first request after start (or an NMT reset) with command
    specifier 7, 0 or 3: abort 0x05040001, and the server goes on."""
    b = Bench()
    if reset is not None:
        b.send(nmt(reset, NODE))
    index, sub, code = _abort(b, request_)
    assert code == ABORT_CS
    if request_[0] >> 5 == 7:
        assert (index, sub) == (0x1000, 0)                 # the request's multiplexer
    assert b.sdo(sdo_upload(NODE, 0x1000, 0)) == ("upload", 0x1000, 0, 0x00020192)
    assert _abort(b, request_)[2] == ABORT_CS              # and after a transfer too


def test_sdo_segments_outside_a_transfer_and_block_transfers_are_aborted() -> None:
    b = Bench()
    # a segmented upload, read to its end: one more segment is no transfer
    assert b.send(sdo_upload(NODE, 0x1008, 0))[0].data[0] == 0x41
    toggle = 0
    while True:
        seg = b.send((0x600 + NODE, bytes([0x60 | toggle << 4]) + bytes(7)))[0].data
        toggle ^= 1
        if seg[0] & 1:
            break
    assert _abort(b, bytes([0x60 | toggle << 4]) + bytes(7))[2] == ABORT_CS
    # a download segment after an expedited download
    assert b.sdo(sdo_download(NODE, 0x6065, 0, 500, 4))[0] == "download-ok"
    assert _abort(b, bytes(8))[2] == ABORT_CS
    # block download and upload (not supported), and the client's abort (no answer)
    assert _abort(b, bytes([0xC0, 0x00, 0x10, 0x00, 0, 0, 0, 0]))[2] == ABORT_CS
    assert _abort(b, bytes([0xA0, 0x00, 0x10, 0x00, 0x7F, 0, 0, 0]))[2] == ABORT_CS
    assert b.send((0x600 + NODE, bytes([0x80, 0x00, 0x10, 0x00, 0, 0, 0, 0x08]))) == []
    # a segmented download with no end stops at 4 KiB: out of memory
    assert b.sdo((0x600 + NODE, bytes([0x21, 0x08, 0x10, 0x00, 0xFF, 0xFF, 0, 0])))[0] == "download-ok"
    toggle = 0
    for _ in range(4096 // 7 + 2):
        out = b.send((0x600 + NODE, bytes([toggle << 4]) + b"x" * 7))
        if out[0].data[0] == 0x80:                     # an abort, not a segment's answer
            break
        assert out[0].data[0] == 0x20 | toggle << 4
        toggle ^= 1
    assert sdo_response(out[0].data)[3] == 0x05040005
    assert b.sdo(sdo_upload(NODE, 0x1000, 0))[3] == 0x00020192


def test_a_malformed_sdo_kills_no_drive_of_the_simulator(peer: Peer, tmp_path: Path) -> None:
    """servoamp-drivesim with drives 4 and 5: the bad request to 4 as its
    first is answered with an abort, and both drives go on."""
    from servoamp.drivesim.__main__ import main
    t = threading.Thread(target=main, args=(["--socket", str(tmp_path / "can.sock"), "--nodes", "4,5"],),
                         daemon=True)
    t.start()
    assert peer.ready.wait(10)
    assert [peer.read().can_id for _ in range(2)] == [0x704, 0x705]
    peer.write(Record(FRAME, 0, 8, 0x604, 1 * MS, bytes([0xE0, 0x00, 0x10, 0x00, 0, 0, 0, 0]), 1))
    answer = peer.read()
    assert answer.can_id == 0x584 and sdo_response(answer.data) == ("abort", 0x1000, 0, ABORT_CS)
    assert peer.read() == Record(DONE, seq=1)
    for seq, node in ((2, 5), (3, 4)):
        peer.write(Record(FRAME, 0, 8, 0x600 + node, (1 + seq) * MS, sdo_upload(node, 0x1000, 0)[1], seq))
        answer = peer.read()
        assert answer.can_id == 0x580 + node and sdo_response(answer.data)[3] == 0x00020192
        assert peer.read() == Record(DONE, seq=seq)
    peer.write(Record(BYE))
    t.join(10)
    assert not t.is_alive()


# --- item 7: PDO mapping validated (CiA 301) ----------------------------------------


def _operational_with_tpdo() -> tuple[Bench, bytes]:
    b = Bench()
    b.send(nmt(NMT_START, NODE))
    out = [f for f in b.send((0x080, b""), MS) if f.can_id == 0x180 + NODE]
    assert len(out) == 1
    return b, out[0].data


@pytest.mark.parametrize("index, sub, value, code", [
    (0x1A00, 1, 0x23450010, 0x06020000),       # no object 0x2345
    (0x1A00, 1, 0x20000410, 0x06090011),       # 0x2000 has no sub-index 4
    (0x1A00, 1, 0x10000020, 0x06040041),       # 0x1000: not mappable
    (0x1A00, 2, 0x60650020, 0x06040041),       # 0x6065: not mappable
    (0x1600, 1, 0x60410010, 0x06040041),       # statusword: read-only, not into an RPDO
    (0x1A00, 1, 0x60410020, 0x06040041),       # 32 bits of a 16-bit object
    (0x1A00, 1, 0x6041000C, 0x06040041),       # not whole bytes
    (0x1A00, 1, 0x60410000, 0x06040041),       # no bits
    (0x1A00, 0, 3, 0x06040042),                # more entries than there are
    (0x1600, 0, 0xFF, 0x06040042),
    (0x1800, 2, 245, 0x06090030),              # reserved transmission types
    (0x1400, 2, 253, 0x06090030),
])
def test_invalid_pdo_mapping_is_aborted_and_the_next_sync_works(index: int, sub: int, value: int,
                                                                 code: int) -> None:
    b, tpdo = _operational_with_tpdo()
    size = 1 if sub == 0 or (index in (0x1400, 0x1800) and sub == 2) else 4
    assert b.sdo(sdo_download(NODE, index, sub, value, size)) == ("abort", index, sub, code)
    out = [f for f in b.send((0x080, b""), MS) if f.can_id == 0x180 + NODE]
    assert [len(f.data) for f in out] == [len(tpdo)]      # the mapping in force is unchanged
    assert b.drive.read(index, sub) != value


def test_valid_remapping_is_taken() -> None:
    """CiA 301's procedure (PDO invalid, sub 0 = 0, entries, sub 0, valid):
    TPDO1 carries the error code and the position actual."""
    b, _ = _operational_with_tpdo()
    for index, sub, value, size in ((0x1800, 1, 0x80000180 + NODE, 4), (0x1A00, 0, 0, 1),
                                    (0x1A00, 1, 0x603F0010, 4), (0x1A00, 0, 2, 1),
                                    (0x1800, 1, 0x180 + NODE, 4)):
        assert b.sdo(sdo_download(NODE, index, sub, value, size))[0] == "download-ok", (index, sub)
    out = [f for f in b.send((0x080, b""), MS) if f.can_id == 0x180 + NODE]
    assert len(out) == 1 and struct.unpack("<Hi", out[0].data) == (0, 0)


# --- item 8: the control socket never blocks the lockstep loop ------------------------


def test_a_silent_control_connection_does_not_block_the_loop(tmp_path: Path) -> None:
    drives = [Drive(1)]
    ctl = Control(str(tmp_path / "d.ctl"), drives)
    silent = []
    try:
        for _ in range(4):
            s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            s.settimeout(5)
            s.connect(ctl.path)
            silent.append(s)
        silent[0].sendall(b"sta")                      # half a request
        t0 = time.monotonic()
        for _ in range(20):
            ctl.poll()
        assert time.monotonic() - t0 < 0.1             # 20 polls, 4 silent connections
        # the half request completed later is answered, on a later poll
        silent[0].sendall(b"te\n")
        silent[0].settimeout(5)
        got = b""
        deadline = time.monotonic() + 5
        while not got.endswith(b"\n") and time.monotonic() < deadline:
            ctl.poll()
            try:
                got += silent[0].recv(256, socket.MSG_DONTWAIT)
            except BlockingIOError:
                time.sleep(0.005)
        assert got.startswith(b"ok 1: ")
        # a request on a new connection meanwhile, from another thread
        answer: list[str] = []
        th = threading.Thread(target=lambda: answer.append(control_request(ctl.path, "state", 5)))
        th.start()
        while th.is_alive():
            ctl.poll()
            time.sleep(0.005)
        assert answer and answer[0].startswith("ok 1: ")
    finally:
        for s in silent:
            s.close()
        ctl.close()


def test_control_connections_are_bounded_in_number_and_time(tmp_path: Path,
                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    from servoamp.drivesim import __main__ as dmain
    monkeypatch.setattr(dmain, "CONTROL_IDLE_S", 0.05)
    ctl = Control(str(tmp_path / "d.ctl"), [Drive(1)])
    socks = []
    try:
        for _ in range(dmain.CONTROL_MAX_CONNECTIONS + 4):
            s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            s.settimeout(5)
            s.connect(ctl.path)
            socks.append(s)
            ctl.poll()
        assert len(ctl.conns) <= dmain.CONTROL_MAX_CONNECTIONS
        time.sleep(0.1)
        ctl.poll()
        assert ctl.conns == {}                          # idle ones closed
        socks[-1].settimeout(5)
        assert socks[-1].recv(256) == b""               # closed by the simulator
    finally:
        for s in socks:
            s.close()
        ctl.close()


# --- item 9: dropped by QEMU: one line, non-zero; BYE: 0 --------------------------------


def _simulator(sock: Path) -> subprocess.Popen[str]:
    env = dict(os.environ, PYTHONPATH=str(TOP / "python"))
    return subprocess.Popen([sys.executable, "-m", "servoamp.drivesim", "--socket", str(sock), "--nodes", "1,2"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)


def _finish(p: subprocess.Popen[str]) -> tuple[int, str]:
    _, err = p.communicate(timeout=20)
    return p.returncode, err


def test_bye_exits_0_quietly(peer: Peer, tmp_path: Path) -> None:
    p = _simulator(tmp_path / "can.sock")
    assert peer.ready.wait(20)
    assert [peer.read().can_id for _ in range(2)] == [0x701, 0x702]
    peer.write(Record(BYE))
    assert _finish(p) == (0, "")


@pytest.mark.parametrize("how", ["close", "reset", "bad-record", "mid-exchange"])
def test_dropped_by_qemu_says_why_in_one_line(peer: Peer, tmp_path: Path, how: str) -> None:
    """QEMU drops a client by closing its socket without BYE (docs/canlink.md,
    "Silence and death"): the simulator says so in one line and exits 3."""
    p = _simulator(tmp_path / "can.sock")
    assert peer.ready.wait(20) and peer.conn is not None
    if how == "close":                                  # EOF at a record boundary
        assert [peer.read().can_id for _ in range(2)] == [0x701, 0x702]
        peer.conn.close()
    elif how == "reset":                                # closed with its boot-ups unread: ECONNRESET
        while len(peer.conn.recv(64, socket.MSG_PEEK)) < 64:
            time.sleep(0.01)
        peer.conn.close()
    elif how == "bad-record":
        peer.conn.sendall(b"\x09" + bytes(31))
    else:                                               # a frame, and the link gone before the answer
        peer.write(Record(FRAME, 0, 8, 0x601, MS, sdo_upload(1, 0x1000, 0)[1], 1))
        peer.conn.close()
    rc, err = _finish(p)
    assert rc == 3, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert err.startswith("servoamp-drivesim: ") and "QEMU" in err


# --- item 10: EMCY, the EDS, the fault reaction -------------------------------------------


def test_pdo_length_emcy_agrees_with_the_error_register_and_is_reset() -> None:
    b = Bench()
    b.send(nmt(NMT_START, NODE))
    out = b.send((0x200 + NODE, struct.pack("<H", 6)))
    code, reg = emcy(out[0].data)
    assert code == 0x8210 and reg == b.drive.read(0x1001) and reg & 0x10   # communication error
    # the next RPDO of the right length: the error is gone, EMCY 0000
    out = b.send(rpdo1(NODE, 0x06, 0))
    assert [emcy(f.data) for f in out if f.can_id == 0x80 + NODE] == [(0, 0)]
    assert b.drive.read(0x1001) == 0
    # or a fault reset (rising edge of controlword bit 7) clears it
    b.send((0x200 + NODE, struct.pack("<H", 6)))
    assert b.drive.read(0x1001) == reg
    b.sdo(sdo_download(NODE, 0x6040, 0, 0x00, 2))
    out = b.send(sdo_download(NODE, 0x6040, 0, 0x80, 2))
    assert [emcy(f.data) for f in out if f.can_id == 0x80 + NODE] == [(0, 0)]
    assert b.drive.read(0x1001) == 0


def test_emcy_register_is_0x1001_through_a_trip_and_its_reset() -> None:
    """Every EMCY carries 0x1001 as it is after the frame that caused it:
    a PDO length error, its end, an over-current trip, the fault reset."""
    b = Bench([Injection(NODE, FaultKind.OVER_CURRENT, 8 * MS)])
    b.enable()
    seen = []
    for frame, dt in [((0x200 + NODE, b"\x01"), 50_000), ((0x080, b""), 950_000)] * 2 \
            + [(rpdo1(NODE, 0x0F, 0), 50_000), ((0x080, b""), 950_000)] * 8 \
            + [(rpdo1(NODE, 0x00, 0), 50_000), ((0x080, b""), 950_000)] \
            + [(rpdo1(NODE, 0x80, 0), 50_000), ((0x080, b""), 950_000)]:
        for f in b.send(frame, dt):
            if f.can_id == 0x80 + NODE:
                seen.append(emcy(f.data))
                assert seen[-1][1] == b.drive.read(0x1001), seen
    assert seen == [(0x8210, 0x11), (0x8210, 0x11), (0, 0), (0x2310, 0x03), (0, 0)]


def test_following_error_trip_passes_through_fault_reaction_active() -> None:
    b = Bench([Injection(NODE, FaultKind.FOLLOWING_ERROR, 50 * MS)])
    b.enable()
    states = []
    for k in range(200):
        sw, _, out = b.cycle(0x0F, 50 * k)
        states.append(cia402.state_of(sw))
        if states[-1] == State.FAULT:
            break
    assert states[-3:] == [State.OPERATION_ENABLED, State.FAULT_REACTION_ACTIVE, State.FAULT], states[-5:]


def test_over_current_trip_passes_through_fault_reaction_active() -> None:
    b = Bench([Injection(NODE, FaultKind.OVER_CURRENT, 30 * MS)])
    b.enable()
    states = []
    for _ in range(60):
        sw, _, _ = b.cycle(0x0F, 0)
        states.append(cia402.state_of(sw))
        if states[-1] == State.FAULT:
            break
    assert states[-2:] == [State.FAULT_REACTION_ACTIVE, State.FAULT], states[-5:]


def test_tpdo_remote_request_and_event_driven_transmission() -> None:
    """What the EDS advertises works: a remote frame on TPDO1 (its COB-ID
    allows it) and transmission type 255."""
    b, tpdo = _operational_with_tpdo()
    # RTR on TPDO1 (COB-ID bit 30 clear): the TPDO now
    out = b.drive.on_frame(0x180 + NODE, b"", b.t + 1000, rtr=True)
    assert [(f.can_id, f.data) for f in out] == [(0x180 + NODE, tpdo)]
    # not allowed with bit 30 set: no answer
    assert b.sdo(sdo_download(NODE, 0x1800, 1, 0x40000180 + NODE, 4))[0] == "download-ok"
    assert b.drive.on_frame(0x180 + NODE, b"", b.t + 2000, rtr=True) == []
    # transmission type 255: sent when its data changes, not at SYNC
    assert b.sdo(sdo_download(NODE, 0x1800, 2, 255, 1))[0] == "download-ok"
    assert [f for f in b.send((0x080, b""), MS) if f.can_id == 0x180 + NODE] == []
    out = b.send(rpdo1(NODE, 0x06, 0), 50_000)                 # latched ...
    assert [f for f in out if f.can_id == 0x180 + NODE] == []
    out = b.send((0x080, b""), 950_000)                        # ... applied: Ready to switch on
    tp = [f for f in out if f.can_id == 0x180 + NODE]
    assert len(tp) == 1 and cia402.state_of(tpdo1(tp[0].data)[0]) == State.READY_TO_SWITCH_ON
    assert [f for f in b.send((0x080, b""), MS) if f.can_id == 0x180 + NODE] == []   # no change


def test_node_guarding_answers_and_life_guarding_trips() -> None:
    """The EDS's 0x100C/0x100D: node guarding and life guarding."""
    b = Bench()
    guard = 0x700 + NODE
    answers = [b.drive.on_frame(guard, b"", b.t + k * 10 * MS, rtr=True) for k in range(1, 4)]
    assert [[f.data for f in a if f.can_id == guard] for a in answers] == [[b"\x7f"], [b"\xff"], [b"\x7f"]]
    b.t += 30 * MS
    # guard time 20 ms, life time factor 3: no guarding for 60 ms is a life guarding event
    assert b.sdo(sdo_download(NODE, 0x100C, 0, 20, 2))[0] == "download-ok"
    assert b.sdo(sdo_download(NODE, 0x100D, 0, 3, 1))[0] == "download-ok"
    b.drive.on_frame(guard, b"", b.t, rtr=True)
    out = b.send((0x7E5, b""), 59 * MS)
    assert [f for f in out if f.can_id == 0x80 + NODE] == []
    out = b.send((0x7E5, b""), 2 * MS)
    assert [emcy(f.data) for f in out if f.can_id == 0x80 + NODE] == [(0x8130, 0x11)]
    assert b.drive.read(0x1001) == 0x11
    out = b.drive.on_frame(guard, b"", b.t + MS, rtr=True)      # guarded again: reset
    assert [emcy(f.data) for f in out if f.can_id == 0x80 + NODE] == [(0, 0)]


def test_heartbeat_consumer_trips_when_the_producer_goes_silent() -> None:
    """The EDS's 0x1016, and 0x1003 holding the last error."""
    b = Bench()
    # node 0x7F's heartbeat, 50 ms
    assert b.sdo(sdo_download(NODE, 0x1016, 1, 0x7F << 16 | 50, 4))[0] == "download-ok"
    out = b.send((0x77F, b"\x05"), 10 * MS)
    out += b.send((0x77F, b"\x05"), 40 * MS)
    out += b.send((0x7E5, b""), 49 * MS)
    assert [f for f in out if f.can_id == 0x80 + NODE] == []
    out = b.send((0x7E5, b""), 2 * MS)
    assert [emcy(f.data) for f in out if f.can_id == 0x80 + NODE] == [(0x8130, 0x11)]
    out = b.send((0x77F, b"\x05"), MS)
    assert [emcy(f.data) for f in out if f.can_id == 0x80 + NODE] == [(0, 0)]
    assert b.sdo(sdo_upload(NODE, 0x1003, 1))[3] == 0x8130        # the last error


# --- the fuzz harness ----------------------------------------------------------------------

_IDS = [0x000, 0x080, 0x080 + NODE, 0x180 + NODE, 0x200 + NODE, 0x580 + NODE, 0x600 + NODE,
        0x700 + NODE, 0x77F, 0x601]
_MULTIPLEXERS = [(0x1000, 0), (0x1001, 0), (0x1003, 0), (0x1003, 1), (0x1005, 0), (0x1006, 0), (0x1008, 0),
                 (0x100C, 0), (0x100D, 0), (0x1016, 1), (0x1017, 0), (0x1400, 1), (0x1400, 2), (0x1600, 0),
                 (0x1600, 1), (0x1600, 2), (0x1800, 1), (0x1800, 2), (0x1A00, 0), (0x1A00, 1), (0x1A00, 2),
                 (0x2000, 1), (0x2000, 2), (0x2000, 3), (0x6040, 0), (0x6060, 0), (0x6065, 0), (0x6066, 0),
                 (0x6073, 0), (0x607A, 0), (0x2345, 0), (0x1A00, 7)]


@st.composite
def _frames(draw: st.DrawFn) -> tuple[int, bytes, bool, int]:
    """(can_id, data, rtr, dt_ns): mostly SDO requests to the object
    dictionary's interesting objects, NMT, SYNC and PDOs, some random."""
    kind = draw(st.sampled_from(["sdo", "sdo", "sdo", "nmt", "sync", "pdo", "any"]))
    dt = draw(st.integers(0, 200 * MS))
    if kind == "sdo":
        index, sub = draw(st.sampled_from(_MULTIPLEXERS))
        cmd = draw(st.sampled_from([0x2F, 0x2B, 0x23, 0x22, 0x21, 0x40, 0x60, 0x70, 0x00, 0x10, 0x01,
                                    0x80, 0xA0, 0xC0, 0xE0]) | st.integers(0, 255))
        value = draw(st.integers(0, 0xFFFFFFFF) | st.sampled_from([0, 1, 2, 3, 8, 0x80, 0xFF, 255, 254]))
        return 0x600 + NODE, struct.pack("<BHBI", cmd, index, sub, value), False, dt
    if kind == "nmt":
        return 0, bytes([draw(st.sampled_from([1, 2, 0x80, 0x81, 0x82, 0x7F])),
                         draw(st.sampled_from([0, NODE, 5]))]), False, dt
    if kind == "sync":
        return 0x080, b"", False, draw(st.sampled_from([MS, 100_000, 0, 5 * MS]))
    if kind == "pdo":
        return (0x200 + NODE, struct.pack("<Hi", draw(st.sampled_from([0x06, 0x07, 0x0F, 0x80, 0x02, 0])),
                                          draw(st.integers(-(1 << 31), (1 << 31) - 1))), False, dt)
    can_id = draw(st.sampled_from(_IDS) | st.integers(0, 0x7FF))
    rtr = draw(st.booleans())
    return can_id, b"" if rtr else draw(st.binary(max_size=8)), rtr, dt


# derandomized (the same examples every run: not flaky); a longer, random run:
# DRIVESIM_FUZZ_EXAMPLES=20000 DRIVESIM_FUZZ_RANDOM=1 pytest -k fuzz tests/fieldbus/test_drivesim_misuse.py
@settings(max_examples=int(os.environ.get("DRIVESIM_FUZZ_EXAMPLES", "300")), deadline=None, database=None,
          derandomize=not os.environ.get("DRIVESIM_FUZZ_RANDOM"), suppress_health_check=list(HealthCheck))
@given(st.lists(_frames(), min_size=1, max_size=60),
       st.sampled_from([(), (Injection(NODE, FaultKind.FOLLOWING_ERROR, 20 * MS),),
                        (Injection(NODE, FaultKind.OVER_CURRENT, 5 * MS),)]))
def test_fuzz_no_frame_stops_the_drive(frames: list[tuple[int, bytes, bool, int]],
                                       faults: tuple[Injection, ...]) -> None:
    """Whatever the bus carries: no exception, an 8-byte SDO request to the
    drive gets at most one answer (exactly one unless it is the client's
    abort or the drive is stopped), every EMCY's register is 0x1001's."""
    d = Drive(NODE, faults=faults)
    t = 0
    d.boot(t)
    for can_id, data, rtr, dt in frames:
        t += dt
        out: list[Frame] = d.on_frame(can_id, data, t, rtr=rtr)
        assert all(len(f.data) <= 8 for f in out)
        emcys = [f for f in out if f.can_id == 0x80 + NODE]
        if emcys:
            assert emcys[-1].data[2] == d.read(0x1001)
        if can_id == 0x600 + NODE and len(data) == 8 and not rtr and d.nmt != d.nmt.STOPPED:
            n = sum(f.can_id == 0x580 + NODE for f in out)
            assert n == (0 if data[0] >> 5 == 4 else 1), (data.hex(), out)
    # and the drive still answers
    d.on_frame(0, bytes([0x80, NODE]), t + 1)
    out = d.on_frame(0x600 + NODE, sdo_upload(NODE, 0x1000, 0)[1], t + 2)
    assert [sdo_response(f.data) for f in out if f.can_id == 0x580 + NODE] == [("upload", 0x1000, 0, 0x00020192)]
