# SPDX-License-Identifier: MIT
"""servoamp.canlink's records and client, and the python-can interface
``servoamp`` (servoamp.canbus), against a canlink peer written here from
docs/canlink.md (the end-to-end tests run the real QEMU): records packed
and refused, HELLO both ways, passive and active clients, DONE sent when
the application reads again, BYE."""

from __future__ import annotations

import socket
import struct
import threading
from pathlib import Path
from typing import Iterator

import can
import pytest

from fieldbus_helpers import Peer
from servoamp import canlink
from servoamp.canlink import BYE, DONE, ERROR, FRAME, HELLO, ProtocolError, Record


def test_record_roundtrip_and_layout() -> None:
    rec = Record(FRAME, canlink.FLAG_EFF, 3, 0x1234567, 123456789, b"\x01\x02\x03", 42)
    raw = canlink.pack(rec)
    assert len(raw) == 32
    assert raw[:4] == bytes([2, 1, 3, 0])
    assert struct.unpack_from("<IQ", raw, 4) == (0x1234567, 123456789)
    assert raw[16:24] == b"\x01\x02\x03\0\0\0\0\0" and struct.unpack_from("<II", raw, 24) == (42, 0)
    assert canlink.unpack(raw) == rec


def test_error_and_done_records() -> None:
    # ERROR carries the destroyed frame's identifier, dlc and data, like FRAME
    err = Record(ERROR, canlink.FLAG_EFF, 2, 0x1ABCDEF, 5_000, b"\x01\x02", 9)
    raw = canlink.pack(err)
    assert raw[:4] == bytes([5, 1, 2, 0])
    assert canlink.unpack(raw) == err
    # DONE: flag bit 0 = the client destroys the frame; no other flag
    done = canlink.unpack(canlink.pack(Record(DONE, canlink.DONE_ERROR, seq=4)))
    assert done.destroyed and not Record(DONE, seq=4).destroyed
    with pytest.raises(ProtocolError, match="DONE flags"):
        canlink.pack(Record(DONE, 0x02, seq=4))
    with pytest.raises(ProtocolError, match="ERROR flags"):
        canlink.pack(Record(ERROR, canlink.FLAG_INFO, 0, 0x80, 1, b"", 1))
    with pytest.raises(ProtocolError, match="dlc 9"):
        canlink.unpack(bytes([5, 0, 9, 0]) + bytes(28))


@pytest.mark.parametrize("mutate, why", [
    (lambda b: b.__setitem__(0, 9), "unknown record type"),
    (lambda b: b.__setitem__(2, 9), "dlc 9"),
    (lambda b: b.__setitem__(3, 1), "reserved"),
    (lambda b: b.__setitem__(28, 1), "reserved"),
    (lambda b: b.__setitem__(4 + 1, 0x08), "can_id 0x800"),       # 0x800 standard
    (lambda b: b.__setitem__(7, 0x20), "can_id"),                  # over 29 bits
    (lambda b: b.__setitem__(23, 0xFF), "past the dlc"),
    (lambda b: b.__setitem__(1, 0x40), "flags"),
])
def test_bad_records_are_refused(mutate, why) -> None:  # type: ignore[no-untyped-def]
    raw = bytearray(canlink.pack(Record(FRAME, 0, 2, 0x7FF, 1, b"\xaa\xbb", 1)))
    if why == "can_id":
        raw[1] = canlink.FLAG_EFF
    mutate(raw)
    with pytest.raises(ProtocolError):
        canlink.unpack(bytes(raw))
    with pytest.raises(ProtocolError):
        canlink.unpack(bytes(raw[:31]))


def test_the_interface_is_registered() -> None:
    assert "servoamp" in can.VALID_INTERFACES


def test_passive_bus(peer: Peer, tmp_path: Path) -> None:
    with can.Bus(interface="servoamp", channel=str(tmp_path / "can.sock")) as bus:
        assert peer.ready.wait(5) and peer.hello is not None
        assert not peer.hello.active and peer.hello.data == b"pycan"
        assert bus.bitrate == 500_000   # type: ignore[attr-defined]
        peer.write(Record(FRAME, 0, 2, 0x181, 1_500_000_000, b"\x12\x34", 7))
        peer.write(Record(FRAME, canlink.FLAG_INFO | canlink.FLAG_EFF | canlink.FLAG_RTR, 4, 0x1ABCDEF, 1_600_000_000))
        m = bus.recv(5)
        assert m is not None and m.arbitration_id == 0x181 and bytes(m.data) == b"\x12\x34"
        assert m.timestamp == 1.5 and not m.is_extended_id and m.is_rx
        m = bus.recv(5)
        assert m is not None and m.is_extended_id and m.is_remote_frame and m.dlc == 4
        assert bus.recv(0.05) is None
        assert not peer.pending()                        # a passive client sends no DONE
        bus.send(can.Message(arbitration_id=0x601, data=b"\x40\x00\x10\x00\0\0\0\0", is_extended_id=False))
        rec = peer.read()
        assert (rec.type, rec.can_id, rec.data, rec.t_ns) == (FRAME, 0x601, b"\x40\x00\x10\x00\0\0\0\0", 0)
    assert peer.read().type == BYE


def test_active_bus_sends_done_when_the_application_reads_again(peer: Peer, tmp_path: Path) -> None:
    with can.Bus(interface="servoamp", channel=str(tmp_path / "can.sock"), active=True) as bus:
        assert peer.ready.wait(5) and peer.hello is not None and peer.hello.active
        peer.write(Record(FRAME, 0, 0, 0x080, 1000, b"", 1))
        assert bus.recv(5) is not None
        assert not peer.pending()                        # no DONE yet
        bus.send(can.Message(arbitration_id=0x181, data=b"\x01", is_extended_id=False))
        assert peer.read().can_id == 0x181               # the answer ...
        assert bus.recv(0.05) is None
        assert peer.read() == Record(DONE, seq=1)        # ... then DONE, on the next recv
        peer.write(Record(FRAME, canlink.FLAG_INFO, 1, 0x181, 2000, b"\x01", 0))
        assert bus.recv(5) is not None
        assert bus.recv(0.05) is None
        assert not peer.pending()                        # none for an INFO frame
        peer.write(Record(FRAME, 0, 0, 0x080, 3000, b"", 2))
        assert bus.recv(5) is not None
    assert peer.read() == Record(DONE, seq=2)            # shutdown pays the DONE owed
    assert peer.read().type == BYE


def test_answers_carry_the_seq_of_their_frame(peer: Peer, tmp_path: Path) -> None:
    """docs/canlink.md: an active client's frames sent between a guest
    frame and its DONE carry that frame's seq (its answers, charged to it);
    any other frame, such as an answer to an INFO frame, carries 0 (outside
    an exchange: QEMU never charges it to a guest frame)."""
    link = canlink.Link.connect(str(tmp_path / "can.sock"), active=True, name="drive")
    try:
        assert peer.ready.wait(5)
        link.send_frame(0x701, b"\x00")                          # boot-up
        assert peer.read().seq == 0
        peer.write(Record(FRAME, 0, 0, 0x080, 1000, b"", 41))
        assert link.recv(5) is not None
        link.send_frame(0x181, b"\x01")
        link.send_frame(0x182, b"\x02", seq=0)                   # explicitly outside
        link.done(41)
        assert [(r.can_id, r.type, r.seq) for r in (peer.read(), peer.read(), peer.read())] == \
            [(0x181, FRAME, 41), (0x182, FRAME, 0), (0, DONE, 41)]
        link.send_frame(0x183, b"\x03")                          # after the DONE
        assert peer.read().seq == 0
        peer.write(Record(FRAME, canlink.FLAG_INFO, 0, 0x080, 2000, b"", 0))
        assert link.recv(5) is not None
        link.send_frame(0x184, b"\x04")                          # answers an INFO frame
        assert peer.read().seq == 0
    finally:
        link.close()


def test_a_destroyed_frame_is_an_error_frame_and_owes_no_done(peer: Peer, tmp_path: Path) -> None:
    with can.Bus(interface="servoamp", channel=str(tmp_path / "can.sock"), active=True) as bus:
        assert peer.ready.wait(5)
        peer.write(Record(FRAME, 0, 0, 0x080, 1000, b"", 1))
        assert bus.recv(5) is not None
        peer.write(Record(ERROR, 0, 0, 0x080, 1061, b"", 1))
        m = bus.recv(5)
        assert m is not None and m.is_error_frame and m.arbitration_id == 0x080
        assert m.timestamp == pytest.approx(1.061e-6)
        assert peer.read() == Record(DONE, seq=1)        # the DONE of the FRAME only
        assert bus.recv(0.05) is None
        assert not peer.pending()
    assert peer.read().type == BYE


def test_listen_only_bus_holds_the_guest_and_sends_nothing(peer: Peer, tmp_path: Path) -> None:
    with can.Bus(interface="servoamp", channel=str(tmp_path / "can.sock"), listen_only="true") as bus:
        assert peer.ready.wait(5) and peer.hello is not None
        assert peer.hello.active and peer.hello.listen
        assert "listen-only" in bus.channel_info
        peer.write(Record(FRAME, 0, 0, 0x080, 1000, b"", 1))
        assert bus.recv(5) is not None
        assert bus.recv(0.05) is None
        assert peer.read() == Record(DONE, seq=1)        # held like an active client
        with pytest.raises(can.CanOperationError, match="listen-only"):
            bus.send(can.Message(arbitration_id=0x181, data=b"\x01", is_extended_id=False))
        assert not peer.pending()
    assert peer.read().type == BYE


def test_bye_and_bad_records_end_the_bus(peer: Peer, tmp_path: Path) -> None:
    bus = can.Bus(interface="servoamp", channel=str(tmp_path / "can.sock"))
    try:
        assert peer.ready.wait(5)
        assert peer.conn is not None
        peer.conn.sendall(b"\x02\x00\x09" + bytes(29))   # dlc 9
        with pytest.raises(can.CanOperationError):
            bus.recv(5)
    finally:
        bus.shutdown()


def test_drivesim_serves_as_an_active_client(peer: Peer, tmp_path: Path) -> None:
    from servoamp.drivesim.__main__ import main
    t = threading.Thread(target=main, args=(["--socket", str(tmp_path / "can.sock"), "--nodes", "4,5"],),
                         daemon=True)
    t.start()
    assert peer.ready.wait(10) and peer.hello is not None and peer.hello.active
    assert [peer.read().can_id for _ in range(2)] == [0x704, 0x705]            # boot-up
    peer.write(Record(FRAME, 0, 8, 0x605, 1_000_000, bytes([0x40, 0x00, 0x10, 0, 0, 0, 0, 0]), 1))
    answer = peer.read()
    assert answer.can_id == 0x585 and answer.data[:4] == bytes([0x43, 0x00, 0x10, 0x00])
    assert struct.unpack_from("<I", answer.data, 4)[0] == 0x00020192
    assert peer.read() == Record(DONE, seq=1)
    peer.write(Record(BYE))
    t.join(10)
    assert not t.is_alive()


def test_drivesim_bus_short_destroys_every_frame_for_its_time(peer: Peer, tmp_path: Path) -> None:
    """``--bus-short 0.002:1``: from 2 ms of guest time for 1 ms every guest
    frame ends with DONE ERROR and the drives neither see it nor answer."""
    from servoamp.drivesim.__main__ import main
    t = threading.Thread(target=main, args=(["--socket", str(tmp_path / "can.sock"), "--nodes", "4",
                                             "--bus-short", "0.002:1"],), daemon=True)
    t.start()
    assert peer.ready.wait(10)
    assert peer.read().can_id == 0x704                                         # boot-up
    sdo = bytes([0x40, 0x00, 0x10, 0, 0, 0, 0, 0])
    for seq, t_ns, destroyed in ((1, 1_999_999, False), (2, 2_000_000, True), (3, 2_999_999, True),
                                 (4, 3_000_000, False)):
        peer.write(Record(FRAME, 0, 8, 0x604, t_ns, sdo, seq))
        if destroyed:
            assert peer.read() == Record(DONE, canlink.DONE_ERROR, seq=seq)
            peer.write(Record(ERROR, 0, 8, 0x604, t_ns + 14_000, sdo, seq))   # ignored
        else:
            assert peer.read().can_id == 0x584
            assert peer.read() == Record(DONE, seq=seq)
    peer.write(Record(BYE))
    t.join(10)
    assert not t.is_alive()


def test_mypy_strict() -> None:
    """The canlink client, the python-can interface, the drive simulator
    and these tests are mypy --strict clean."""
    import subprocess
    import sys
    top = Path(__file__).resolve().parents[2]
    mods = [top / "python/servoamp/canlink.py", top / "python/servoamp/canbus.py",
            top / "python/servoamp/canload.py", top / "python/servoamp/drivesim", top / "tests/fieldbus"]
    p = subprocess.run([str(Path(sys.executable).parent / "mypy"), "--strict", *map(str, mods)],
                       capture_output=True, text=True, cwd=top, timeout=600)
    assert p.returncode == 0, p.stdout + p.stderr
