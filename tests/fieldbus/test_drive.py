# SPDX-License-Identifier: MIT
"""The simulated CiA 402 drive (servoamp.drivesim) without QEMU: frames in
with their guest times, frames out. State machine, NMT, SDO on the object
dictionary of the EDS, SYNC/RPDO/TPDO, heartbeat on guest time, the motor
model, the injected faults with their EMCY codes, and determinism."""

from __future__ import annotations

import struct

import pytest

from fieldbus_helpers import (MS, NODE, NMT_PRE_OP, NMT_RESET_NODE, NMT_START, NMT_STOP, Bench, emcy,
                              nmt, rpdo1, sdo_download, sdo_response, sdo_upload, tpdo1)
from servoamp.drivesim import cia402
from servoamp.drivesim.cia402 import State
from servoamp.drivesim.drive import Drive, FaultKind, Frame, Injection, parse_reset_cycles
from servoamp.drivesim.model import Motor



def test_controlword_transitions() -> None:
    t = cia402.transition
    assert t(State.SWITCH_ON_DISABLED, 0x06, 0) == State.READY_TO_SWITCH_ON
    assert t(State.READY_TO_SWITCH_ON, 0x07, 0x06) == State.SWITCHED_ON
    assert t(State.SWITCHED_ON, 0x0F, 0x07) == State.OPERATION_ENABLED
    assert t(State.OPERATION_ENABLED, 0x07, 0x0F) == State.SWITCHED_ON
    assert t(State.OPERATION_ENABLED, 0x06, 0x0F) == State.READY_TO_SWITCH_ON
    assert t(State.OPERATION_ENABLED, 0x02, 0x0F) == State.QUICK_STOP_ACTIVE
    assert t(State.OPERATION_ENABLED, 0x00, 0x0F) == State.SWITCH_ON_DISABLED
    assert t(State.QUICK_STOP_ACTIVE, 0x0F, 0x02) == State.OPERATION_ENABLED
    assert t(State.QUICK_STOP_ACTIVE, 0x00, 0x02) == State.SWITCH_ON_DISABLED
    assert t(State.SWITCH_ON_DISABLED, 0x0F, 0) == State.SWITCH_ON_DISABLED
    assert t(State.FAULT, 0x80, 0x00) == State.SWITCH_ON_DISABLED        # rising edge
    assert t(State.FAULT, 0x80, 0x80) == State.FAULT                     # no edge
    assert t(State.FAULT, 0x0F, 0x00) == State.FAULT
    assert t(State.FAULT_REACTION_ACTIVE, 0x80, 0) == State.FAULT_REACTION_ACTIVE
    for state, bits in cia402.STATE_BITS.items():
        assert cia402.state_of(bits | cia402.SW_REMOTE | cia402.SW_VOLTAGE_ENABLED * (state != State.FAULT)) in (state, None)
        assert cia402.state_of(bits) == state


def test_boot_up_nmt_and_heartbeat_on_guest_time() -> None:
    b = Bench()
    assert b.boot == [Frame(0x700 + NODE, b"\x00")]
    assert b.drive.read(0x1017) == 100
    beats: list[tuple[int, bytes]] = []
    for _ in range(25):                          # a frame every 10 ms of guest time
        beats += [(b.t, f.data) for f in b.send((0x7E5, b""), 10 * MS) if f.can_id == 0x700 + NODE]
    assert [t for t, _ in beats] == [100 * MS, 200 * MS]
    assert all(d == b"\x7f" for _, d in beats)   # pre-operational
    b.send(nmt(NMT_START, 0))
    assert b.drive.read(0x6041) & 0x4F == 0x40    # switch on disabled
    out = b.send((0x7E5, b""), 60 * MS)           # t = 310 ms
    assert [f.data for f in out if f.can_id == 0x700 + NODE] == [b"\x05"]
    b.send(nmt(NMT_STOP, NODE))
    assert b.send(sdo_upload(NODE, 0x1000, 0)) == []     # stopped: no SDO
    b.send(nmt(NMT_PRE_OP, NODE + 1))                    # another node's
    assert b.send(sdo_upload(NODE, 0x1000, 0)) == []
    b.send(nmt(NMT_PRE_OP, NODE))
    assert b.sdo(sdo_upload(NODE, 0x1000, 0)) == ("upload", 0x1000, 0, 0x00020192)
    out = b.send(nmt(NMT_RESET_NODE, NODE))
    assert Frame(0x700 + NODE, b"\x00") in out


def test_sdo_reads_and_writes_the_object_dictionary() -> None:
    b = Bench()
    assert b.sdo(sdo_upload(NODE, 0x1018, 4)) == ("upload", 0x1018, 4, NODE)
    assert b.sdo(sdo_upload(NODE, 0x1600, 1)) == ("upload", 0x1600, 1, 0x60400010)
    assert b.sdo(sdo_upload(NODE, 0x1A00, 2)) == ("upload", 0x1A00, 2, 0x60640020)
    assert b.sdo(sdo_upload(NODE, 0x1400, 1)) == ("upload", 0x1400, 1, 0x200 + NODE)
    assert b.sdo(sdo_upload(NODE, 0x6502, 0)) == ("upload", 0x6502, 0, 0x80)
    assert b.sdo(sdo_download(NODE, 0x6060, 0, 8, 1))[0] == "download-ok"
    assert b.sdo(sdo_upload(NODE, 0x6061, 0)) == ("upload", 0x6061, 0, 8)
    assert b.sdo(sdo_download(NODE, 0x6060, 0, 1, 1)) == ("abort", 0x6060, 0, 0x06090030)
    assert b.sdo(sdo_download(NODE, 0x6041, 0, 1, 2))[3] == 0x06010002     # read only
    assert b.sdo(sdo_upload(NODE, 0x5000, 0))[3] == 0x06020000               # no object
    assert b.sdo(sdo_download(NODE, 0x6065, 0, 500, 4))[0] == "download-ok"
    assert b.drive.read(0x6065) == 500
    # the statusword through SDO, and the controlword too
    assert b.sdo(sdo_download(NODE, 0x6040, 0, 0x06, 2))[0] == "download-ok"
    assert b.sdo(sdo_upload(NODE, 0x6041, 0))[3] & 0x6F == 0x21


def test_pdos_only_in_operational_and_enable_sequence() -> None:
    b = Bench()
    assert b.send(rpdo1(NODE, 0x06, 0)) == []
    assert b.send((0x080, b""), MS) == []                   # pre-operational: no TPDO
    b.enable()
    assert b.drive.state == State.OPERATION_ENABLED
    sw, pos, _ = b.cycle(0x0F, 0)
    assert sw & 0x6F == 0x27 and sw & cia402.SW_CSP_FOLLOWING and pos == 0


def test_position_follows_a_ramp_and_target() -> None:
    b = Bench()
    b.enable()
    target = 0
    positions = []
    for k in range(300):                                  # 300 ms, 20 counts/ms ramp, then hold
        target = min(20 * k, 4000)
        sw, pos, _ = b.cycle(0x0F, target)
        positions.append(pos)
        assert cia402.state_of(sw) == State.OPERATION_ENABLED
        assert abs(b.drive.read(0x60F4)) <= 2000
    assert abs(positions[-1] - 4000) <= 2
    assert b.drive.read(0x6064) == positions[-1]
    assert max(positions) < 4000 * 1.05                   # overshoot at the ramp end only a little


def test_following_error_trip_sends_emcy_8611() -> None:
    b = Bench([Injection(NODE, FaultKind.FOLLOWING_ERROR, 50 * MS)])
    b.enable()
    codes = []
    state = State.OPERATION_ENABLED
    for k in range(200):
        sw, _, out = b.cycle(0x0F, 50 * k)
        codes += [emcy(f.data) for f in out if f.can_id == 0x80 + NODE]
        state = cia402.state_of(sw) or state
        if codes:
            break
    assert codes == [(0x8611, 0x21)]
    assert state in (State.FAULT, State.FAULT_REACTION_ACTIVE)
    assert b.drive.read(0x603F) == 0x8611
    assert b.drive.read(0x1001) == 0x21
    sw, _, _ = b.cycle(0x00, 0)
    assert cia402.state_of(sw) == State.FAULT
    # fault reset: EMCY 0000 and Switch on disabled
    sw, _, out = b.cycle(0x80, 0)
    assert [emcy(f.data) for f in out if f.can_id == 0x80 + NODE] == [(0, 0)]
    assert cia402.state_of(sw) == State.SWITCH_ON_DISABLED
    assert b.drive.read(0x603F) == 0


def test_over_current_trip_sends_emcy_2310_at_its_time() -> None:
    b = Bench([Injection(NODE, FaultKind.OVER_CURRENT, 30 * MS)])
    b.enable()
    t_trip = None
    for k in range(60):
        _, _, out = b.cycle(0x0F, 0)
        if any(f.can_id == 0x80 + NODE for f in out):
            e = [emcy(f.data) for f in out if f.can_id == 0x80 + NODE]
            assert e == [(0x2310, 0x03)]
            assert out[0].can_id == 0x80 + NODE           # EMCY before the TPDO
            t_trip = b.t
            break
    assert t_trip is not None and 30 * MS <= t_trip < 30 * MS + 1 * MS + 1


def test_off_bus_drive_goes_silent() -> None:
    b = Bench([Injection(NODE, FaultKind.OFF_BUS, 20 * MS)])
    b.enable()
    silent = 0
    for _ in range(30):
        out = b.send(rpdo1(NODE, 0x0F, 0), 50_000) + b.send((0x080, b""), 950_000)
        silent += not out
    assert b.t > 20 * MS and silent >= 30 - 20 + 5
    assert b.send(sdo_upload(NODE, 0x1000, 0)) == []
    assert b.send((0x7E5, b""), 500 * MS) == []           # no heartbeat either


def test_quick_stop_holds_then_switch_on_disabled() -> None:
    b = Bench()
    b.enable()
    for k in range(50):
        b.cycle(0x0F, 40 * k)
    sw, _, _ = b.cycle(0x02, 2000)
    assert cia402.state_of(sw) == State.QUICK_STOP_ACTIVE
    for _ in range(200):
        sw, _, _ = b.cycle(0x02, 2000)
        if cia402.state_of(sw) == State.SWITCH_ON_DISABLED:
            break
    assert cia402.state_of(sw) == State.SWITCH_ON_DISABLED


def test_deterministic() -> None:
    def run() -> list[tuple[int, bytes]]:
        b = Bench([Injection(NODE, FaultKind.FOLLOWING_ERROR, 80 * MS)])
        b.enable()
        frames = []
        for k in range(150):
            frames += [(f.can_id, f.data) for f in b.cycle(0x0F, 37 * k)[2]]
        return frames
    assert run() == run()


def test_motor_model_settles_and_limits_acceleration() -> None:
    m = Motor(bandwidth_hz=40, damping=0.8, accel_rated=1e6, max_current_pm=2000)
    m.step(0, 1000, 0.001, True)
    for _ in range(200):
        m.step(1000, 1000, 0.001, True)
    assert abs(m.pos - 1000) < 0.5 and abs(m.vel) < 1
    m2 = Motor(accel_rated=1e3, max_current_pm=1000)
    m2.step(0, 1e6, 0.01, True)
    assert abs(m2.acc) <= 1e3 and m2.vel <= 10.0 + 1e-9
    assert m2.current_pm == pytest.approx(1000)


def _tripped(cycles: int | None) -> Bench:
    """A drive in Fault (over-current), its fault reset taking ``cycles``."""
    b = Bench([Injection(NODE, FaultKind.OVER_CURRENT, 5 * MS)], fault_reset_cycles=cycles)
    b.enable()
    for _ in range(3):
        sw, _, _ = b.cycle(0x0F, 0)
    assert cia402.state_of(sw) == State.FAULT and b.drive.read(0x603F) == 0x2310
    sw, _, _ = b.cycle(0x00, 0)                         # bit 7 clear before the edge
    return b


@pytest.mark.parametrize("cycles", [1, 2, 30, 50])
def test_slow_fault_reset_takes_its_cycles_with_bit_7_held(cycles: int) -> None:
    b = _tripped(cycles)
    states = []
    for k in range(cycles + 3):
        sw, _, out = b.cycle(0x80, 0)                   # the edge, then held
        states.append(cia402.state_of(sw))
        if states[-1] != State.FAULT:
            assert [emcy(f.data) for f in out if f.can_id == 0x80 + NODE] == [(0, 0)]
            break
    # the edge is applied at its SYNC; the drive leaves Fault `cycles` SYNCs later
    assert states == [State.FAULT] * cycles + [State.SWITCH_ON_DISABLED], states
    assert b.drive.read(0x603F) == 0 and b.drive.read(0x1001) == 0


def test_slow_fault_reset_abandoned_without_bit_7_and_never() -> None:
    b = _tripped(5)
    b.cycle(0x80, 0)
    b.cycle(0x80, 0)
    for _ in range(10):                                 # the bit dropped: the reset is abandoned
        sw, _, _ = b.cycle(0x06, 0)
    assert cia402.state_of(sw) == State.FAULT
    for _ in range(6):                                  # a new edge, held: it completes
        sw, _, _ = b.cycle(0x80, 0)
    assert cia402.state_of(sw) == State.SWITCH_ON_DISABLED
    b = _tripped(None)
    for _ in range(500):
        sw, _, _ = b.cycle(0x80, 0)
    assert cia402.state_of(sw) == State.FAULT and b.drive.read(0x603F) == 0x2310
    # the default: at the edge (CiA 402 transition 15)
    b = _tripped(0)
    sw, _, _ = b.cycle(0x80, 0)
    assert cia402.state_of(sw) == State.SWITCH_ON_DISABLED


def test_reset_cycles_parse() -> None:
    assert parse_reset_cycles("30") == (None, 30)
    assert parse_reset_cycles("2:50") == (2, 50)
    assert parse_reset_cycles("never") == (None, None)
    assert parse_reset_cycles("3:never") == (3, None)
    for bad in ("x", "2:", "0:5", "128:5", "2:-1", "2:x:3"):
        with pytest.raises(ValueError):
            parse_reset_cycles(bad)


def test_injection_parse() -> None:
    assert Injection.parse("2:following-error@0.5") == Injection(2, FaultKind.FOLLOWING_ERROR, 500 * MS)
    assert Injection.parse("1:oc@1") == Injection(1, FaultKind.OVER_CURRENT, 1000 * MS)
    assert Injection.parse("7:off-bus@0.25").kind == FaultKind.OFF_BUS
    for bad in ("2:melt@1", "x:fe@1", "2:fe", "0:fe@1", "2:fe@-1"):
        with pytest.raises(ValueError):
            Injection.parse(bad)


def test_rpdo_of_wrong_length_is_refused_with_emcy() -> None:
    b = Bench()
    b.send(nmt(NMT_START, NODE))
    out = b.send((0x200 + NODE, struct.pack("<H", 6)))
    assert [emcy(f.data)[0] for f in out] == [0x8210]


def test_segmented_sdo_upload() -> None:
    b = Bench()
    kind = b.send(sdo_upload(NODE, 0x1008, 0))[0].data
    assert kind[0] == 0x41 and struct.unpack_from("<I", kind, 4)[0] == len(b"servoamp CSP drive")
    text = b""
    toggle = 0
    while True:
        seg = b.send((0x600 + NODE, bytes([0x60 | toggle << 4]) + bytes(7)))[0].data
        assert seg[0] & 0x10 == toggle << 4
        text += seg[1: 8 - ((seg[0] >> 1) & 7)]
        toggle ^= 1
        if seg[0] & 1:
            break
    assert text == b"servoamp CSP drive"
