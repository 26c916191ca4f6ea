# SPDX-License-Identifier: MIT
"""servoamp.canlink.frame_bits: the exact length of a classic CAN frame on
the wire with ISO 11898-1 bit stuffing, checked against a bitstream built
independently here (strings, CRC by polynomial long division, stuffing on
the output stream) and against hand-computed frames and the worst-case
bounds; servoamp.canlink.arbitration_key (the order canlink gives frames
that contend for the bus) against the same bitstream: the frame whose bit
is dominant where the two first differ wins."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from servoamp.canlink import TRAILER_BITS, arbitration_key, frame_bits, frame_bitstream, stuff_count

# x^15 + x^14 + x^10 + x^8 + x^7 + x^4 + x^3 + 1
CRC15_DIVISOR = "1100010110011001"


def crc15(bits: str) -> str:
    """The CRC-15 of ``bits`` by long division of bits * x^15."""
    work = list(bits + "0" * 15)
    for i in range(len(bits)):
        if work[i] == "1":
            for j, d in enumerate(CRC15_DIVISOR):
                work[i + j] = "0" if work[i + j] == d else "1"
    return "".join(work[-15:])


def bitstream(can_id: int, eff: bool, rtr: bool, dlc: int, data: bytes) -> str:
    """SOF .. last CRC bit, unstuffed, '0' dominant."""
    if eff:
        head = "0" + f"{can_id >> 18:011b}" + "11" + f"{can_id & 0x3FFFF:018b}" + ("1" if rtr else "0") + "00"
    else:
        head = "0" + f"{can_id:011b}" + ("1" if rtr else "0") + "00"
    body = head + f"{dlc:04b}" + ("" if rtr else "".join(f"{b:08b}" for b in data))
    return body + crc15(body)


def stuffed(bits: str) -> str:
    """The bits as sent: after five equal bits of the output stream (stuff
    bits included) the complement is inserted."""
    out = ""
    for b in bits:
        out += b
        if len(out) >= 5 and out[-5:] == b * 5:
            out += "1" if b == "0" else "0"
    return out


def reference_bits(can_id: int, eff: bool, rtr: bool, dlc: int, data: bytes) -> int:
    return len(stuffed(bitstream(can_id, eff, rtr, dlc, data))) + 13


def test_crc15_of_a_known_message() -> None:
    # the CRC of the SYNC frame's 19 bits, also by the shift-register form
    body = "0" + "00010000000" + "000" + "0000"
    reg = 0
    for b in body:
        nxt = int(b) ^ (reg >> 14)
        reg = (reg << 1) & 0x7FFF
        if nxt:
            reg ^= 0x4599
    assert crc15(body) == f"{reg:015b}" == "001110000000101"


def test_sync_frame() -> None:
    """SYNC (0x080, dlc 0): 34 bits SOF..CRC + 13 = 47 before stuffing.
    By hand: SOF+id 0 0001 0000000, RTR IDE r0 000, DLC 0000, CRC
    001110000000101; zero runs after the 1 of the id: 7+3+4+2 = 16 zeros
    (stuff after 5, after 5 more, then 6 with the CRC's two: a third),
    then 0 111 0000000 (a fourth after five zeros): 4 stuff bits."""
    assert bitstream(0x080, False, False, 0, b"") == \
        "0" "00010000000" "000" "0000" "001110000000101"
    assert frame_bits(0x080, False, False, 0, b"") == 47 + 4 == 51


def test_known_frames_by_hand() -> None:
    # id 0x7FF, dlc 0: SOF 0 then eleven 1s: a stuff bit after the first
    # five 1s and another after the next five, the 11th 1 starts a run
    bits = bitstream(0x7FF, False, False, 0, b"")
    assert stuffed(bits).startswith("0" "11111" "0" "11111" "0" "1")
    assert len(bits) == 34
    assert frame_bits(0x7FF, False, False, 0, b"") == reference_bits(0x7FF, False, False, 0, b"")
    # all-zero 8-byte standard frame: 98 bits before the trailer
    assert len(bitstream(0x000, False, False, 8, bytes(8))) == 98
    assert frame_bits(0x000, False, False, 8, bytes(8)) == reference_bits(0x000, False, False, 8, bytes(8))
    # extended, 8 bytes: 118 bits before the trailer
    assert len(bitstream(0x1FFFFFFF, True, False, 8, bytes(8))) == 118


def test_remote_frames_carry_no_data_bits() -> None:
    assert frame_bits(0x701, False, True, 1, b"") == reference_bits(0x701, False, True, 1, b"")
    assert len(bitstream(0x701, False, True, 8, b"")) == 34


@settings(max_examples=400, deadline=None)
@given(eff=st.booleans(), rtr=st.booleans(), dlc=st.integers(0, 8), data=st.binary(min_size=8, max_size=8),
       id_bits=st.integers(0, 0x1FFFFFFF))
def test_agrees_with_the_independent_bitstream(eff: bool, rtr: bool, dlc: int, data: bytes, id_bits: int) -> None:
    can_id = id_bits if eff else id_bits & 0x7FF
    payload = b"" if rtr else data[:dlc]
    n = frame_bits(can_id, eff, rtr, dlc, payload)
    assert n == reference_bits(can_id, eff, rtr, dlc, payload)
    unstuffed = (54 if eff else 34) + (0 if rtr else 8 * dlc)
    # at most one stuff bit per 4 bits after the first
    assert unstuffed + 13 <= n <= unstuffed + 13 + (unstuffed - 1) // 4
    assert n <= (160 if eff else 135)


@settings(max_examples=600, deadline=None)
@given(eff=st.booleans(), rtr=st.booleans(), dlc=st.integers(0, 8),
       data=st.lists(st.sampled_from([0x00, 0xFF, 0x0F, 0xF0, 0x83, 0x7C]), min_size=8, max_size=8),
       id_bits=st.sampled_from([0, 0x1FFFFFFF, 0x7FF, 0x1F, 0x3E0, 0x1FFC0000, 0x3FFFF]))
def test_run_counting_equals_canlinks_bit_by_bit_count(eff: bool, rtr: bool, dlc: int, data: list[int],
                                                       id_bits: int) -> None:
    """frame_bits counts stuff bits from runs of equal bits (the bridge
    calls it per frame); canlink's own bit-by-bit frame_bitstream and
    stuff_count are the reference, on payloads and ids of long runs
    (stuff bits at run ends, carried into the next run)."""
    can_id = id_bits if eff else id_bits & 0x7FF
    payload = b"" if rtr else bytes(data[:dlc])
    bits = frame_bitstream(can_id, eff, rtr, dlc, payload)
    assert frame_bits(can_id, eff, rtr, dlc, payload) == len(bits) + stuff_count(bits) + TRAILER_BITS


def test_worst_case_bounds_are_the_known_ones() -> None:
    """47 + 8*8 = 111 unstuffed for a standard 8-byte frame, at most 24
    stuff bits: 135. Extended: 131, at most 29: 160. The largest found
    over many payloads stays inside."""
    worst_std = max(frame_bits(i, False, False, 8, bytes([p] * 8)) for i in range(0, 0x800, 7) for p in (0, 0x0F, 0x78, 0xE1))
    assert 111 < worst_std <= 135
    assert frame_bits(0, False, False, 8, bytes(8)) <= 135


def wins_on_the_wire(a: tuple[int, bool, bool], b: tuple[int, bool, bool]) -> int:
    """-1 if frame a wins arbitration against b, 1 if b wins, 0 if neither
    (the same arbitration field): the first bit after SOF where their
    bitstreams differ, up to the end of the arbitration field (standard: id,
    RTR and IDE, which a standard frame has where an extended one has its
    IDE; extended: base id, SRR, IDE, extension, RTR), is dominant (0) for
    the winner."""
    sa, sb = (bitstream(i, e, r, 0, b"")[1:(33 if e else 14)] for i, e, r in (a, b))
    for x, y in zip(sa, sb):
        if x != y:
            return -1 if x == "0" else 1
    return 0


frames = st.one_of(st.tuples(st.integers(0, 0x7FF), st.just(False), st.booleans()),
                   st.tuples(st.integers(0, 0x1FFFFFFF), st.just(True), st.booleans()),
                   # the same base id as a standard frame
                   st.tuples(st.integers(0, 0x7FF).map(lambda i: i << 18), st.just(True), st.booleans()))


@settings(max_examples=600, deadline=None)
@given(a=frames, b=frames)
def test_arbitration_key_orders_as_the_wire_does(a: tuple[int, bool, bool], b: tuple[int, bool, bool]) -> None:
    ka, kb = arbitration_key(*a), arbitration_key(*b)
    assert (ka > kb) - (ka < kb) == wins_on_the_wire(a, b)


def test_arbitration_by_hand() -> None:
    """Lower id first; with the same id data before remote; with the same
    base id standard before extended."""
    order = [(0x080, False, False), (0x181, False, False), (0x181, False, True),
             (0x181 << 18, True, False), (0x181 << 18, True, True), ((0x181 << 18) | 1, True, False),
             (0x182, False, False), (0x701, False, False)]
    assert sorted(order, key=lambda f: arbitration_key(*f)) == order
