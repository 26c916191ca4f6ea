# SPDX-License-Identifier: MIT
"""The bus time agreement, on the real QEMU: the times canlink gives the
frames (FRAME's t_ns, the end of the frame on the modelled bus) are the
sums of servoamp.canlink.frame_bits times the bit time, frame after frame,
for standard, extended, data and remote frames of every length; a frame a
host tool sends reaches the guest's RX FIFO at exactly its end on the bus
and not 1 ns before. And canopen's Network.connect(interface="servoamp")
works unchanged: a LocalNode answers the guest's SDO request in lockstep."""

from __future__ import annotations

import time
from pathlib import Path

import can
import canopen
import pytest

from fieldbus_helpers import sdo_response, sdo_upload
from fieldbus_qemu import Board, GuestFrame, qemu_binary
from servoamp import canlink
from servoamp.drivesim.drive import EDS

pytestmark = pytest.mark.board

FRAMES = [
    GuestFrame(0x080, b""),
    GuestFrame(0x181, bytes([0x27, 0x02, 0x10, 0x27, 0, 0])),
    GuestFrame(0x7FF, b"\xff" * 8),
    GuestFrame(0x000, b"\x00" * 8),
    GuestFrame(0x555, b"\x55" * 8),
    GuestFrame(0x1ABCDEF, b"\x01\x02\x03\x04\x05", eff=True),
    GuestFrame(0x701, b"", rtr=True, dlc=1),
    GuestFrame(0x1FFFFFFF, b"", eff=True, rtr=True, dlc=8),
    GuestFrame(0x0F0, b"\x0f\xf0\x0f"),
]


def bits(f: GuestFrame) -> int:
    return canlink.frame_bits(f.can_id, f.eff, f.rtr, f.length, b"" if f.rtr else f.data)


@pytest.mark.parametrize("bitrate", [1_000_000, 500_000])
def test_frame_times_are_frame_bits_sums(tmp_path: Path, bitrate: int) -> None:
    board = Board(qemu_binary(), tmp_path, bitrate=bitrate)
    bit_ns = 1_000_000_000 // bitrate
    try:
        link = canlink.Link.connect(str(board.can_sock), name="timing")
        assert link.bitrate == bitrate
        tool = can.Bus(interface="servoamp", channel=str(board.can_sock))
        board.can_init()
        now = board.clock_step(1_000_000)
        for f in FRAMES:                                  # back to back at one guest time
            board.send(f)
        got = [link.recv(10) for _ in FRAMES]
        t = now
        for f, rec in zip(FRAMES, got):
            assert rec is not None and rec.type == canlink.FRAME and not rec.info
            assert (rec.can_id, rec.eff, rec.rtr, rec.dlc, rec.data) == \
                   (f.can_id, f.eff, f.rtr, f.length, b"" if f.rtr else f.data)
            t += bits(f) * bit_ns
            assert rec.t_ns == t, f"{f}: QEMU {rec.t_ns - (t - bits(f) * bit_ns)} ns, frame_bits {bits(f)} bits"
        assert [r.seq for r in got if r is not None] == list(range(got[0].seq, got[0].seq + len(FRAMES)))  # type: ignore[union-attr]

        # a host tool's frame: on the bus once QEMU read it, behind the rest
        board.clock_set(t + 10_000)
        start = board.now
        tool.send(can.Message(arbitration_id=0x123, data=b"\xde\xad\xbe\xef", is_extended_id=False))
        time.sleep(0.5)              # QEMU's main loop reads it while guest time stands (qtest)
        end = start + canlink.frame_bits(0x123, False, False, 4, b"\xde\xad\xbe\xef") * bit_ns
        board.clock_set(end - 1)
        assert board.receive_all() == []
        board.clock_set(end)
        assert board.receive_all() == [GuestFrame(0x123, b"\xde\xad\xbe\xef", dlc=4)]
        info = link.recv(10)
        assert info is not None and info.info and info.can_id == 0x123 and info.seq == 0
        assert info.t_ns == end
        tool.shutdown()
        link.close()
    finally:
        board.close()


def test_canopen_network_connects_unchanged(tmp_path: Path) -> None:
    board = Board(qemu_binary(), tmp_path)
    network = canopen.Network()
    try:
        network.connect(interface="servoamp", channel=str(board.can_sock), active=True)
        node = canopen.LocalNode(6, canopen.import_od(str(EDS), 6))
        network.add_node(node)
        board.can_init()
        now = board.clock_step(1_000_000)
        can_id, data = sdo_upload(6, 0x1018, 2)
        board.send(GuestFrame(can_id, data))              # returns once the LocalNode answered (DONE)
        req_end = now + canlink.frame_bits(can_id, False, False, 8, data) * 1000
        got: list[GuestFrame] = []
        board.clock_set(req_end)
        while not got:                                    # 1 us steps until the answer is in
            assert board.now < req_end + 1_000_000, "no SDO answer"
            board.clock_step(1000)
            got = board.receive_all()
        assert [(f.can_id, sdo_response(f.data)) for f in got] == [(0x586, ("upload", 0x1018, 2, 0x402))]
        # it came at its own end on the bus, right behind the request
        end = req_end + canlink.frame_bits(0x586, False, False, 8, got[0].data) * 1000
        assert board.now - 1000 < end <= board.now
    finally:
        network.disconnect()
        board.close()
