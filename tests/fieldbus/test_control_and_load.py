"""servoamp-drivesim's --control socket (faults injected into a running
simulator) and servoamp.canload (bits and bus load per cycle from a
python-can log file written by python-can's own writer)."""

from __future__ import annotations

import threading
from pathlib import Path

import can
import pytest

from servoamp import canlink, canload
from servoamp.drivesim.__main__ import Control, control_request
from servoamp.drivesim.drive import Drive, FaultKind


def test_control_answers_and_injects(tmp_path: Path) -> None:
    drives = [Drive(1), Drive(2)]
    ctl = Control(str(tmp_path / "d.ctl"), drives)
    stop = threading.Event()

    def poll() -> None:
        while not stop.is_set():
            ctl.poll()
            stop.wait(0.01)

    th = threading.Thread(target=poll, daemon=True)
    th.start()
    try:
        assert control_request(ctl.path, "fault 2 over-current") == "ok fault 2 over-current"
        assert [i.kind for i in drives[1].injections] == [FaultKind.OVER_CURRENT]
        assert drives[0].injections == []
        assert control_request(ctl.path, "fault 2 off") == "ok fault 2 off-bus"
        assert control_request(ctl.path, "fault 9 off").startswith("error: no drive 9")
        assert control_request(ctl.path, "fault x off").startswith("error: node 'x'")
        assert control_request(ctl.path, "fault 1 melt").startswith("error: fault kind 'melt'")
        assert control_request(ctl.path, "reboot").startswith("error: requests are")
        assert control_request(ctl.path, "bus-short 20") == "ok bus-short 20"
        assert ctl.short.next_ms == 20
        assert ctl.short.shorted(10**9)                         # from the next frame on
        assert ctl.short.shorted(10**9 + 20 * 10**6 - 1) and not ctl.short.shorted(10**9 + 20 * 10**6)
        assert control_request(ctl.path, "bus-short 0").startswith("error: bus-short 0")
        assert control_request(ctl.path, "bus-short x").startswith("error: bus-short 'x'")
        assert control_request(ctl.path, "fault-reset 2 30") == "ok fault-reset 2 30"
        assert drives[1].fault_reset_cycles == 30 and drives[0].fault_reset_cycles == 0
        assert control_request(ctl.path, "fault-reset 1 never") == "ok fault-reset 1 never"
        assert drives[0].fault_reset_cycles is None
        assert control_request(ctl.path, "fault-reset 9 3").startswith("error: no drive 9")
        assert control_request(ctl.path, "fault-reset 2 -3").startswith("error: fault reset")
        st = control_request(ctl.path, "state")
        assert st.startswith("ok 1: ") and "; 2: " in st
        assert "fault_reset=never" in st and "fault_reset=30" in st
    finally:
        stop.set()
        th.join()
        ctl.close()
    assert not Path(ctl.path).exists()


def test_injected_fault_applies_with_the_next_frame() -> None:
    d = Drive(3)
    d.boot(0)
    d.inject(FaultKind.OFF_BUS)
    assert not d.off_bus
    d.on_frame(0x080, b"", 1_000_000)
    assert d.off_bus


def _write(path: Path, frames: list[tuple[float, int, bytes]]) -> None:
    with can.Logger(str(path)) as log:
        for t, i, data in frames:
            log(can.Message(timestamp=t, arbitration_id=i, data=data, is_extended_id=False))


@pytest.mark.parametrize("suffix", [".asc", ".blf"])
def test_cycle_load_from_a_log(tmp_path: Path, suffix: str) -> None:
    rpdo, tpdo = b"\x0f\x00\x10\x27\x00\x00", b"\x37\x06\x10\x27\x00\x00"
    frames = []
    for k in range(4):                      # 4 cycles of 1 ms, one drive
        t = 1.0 + k * 1e-3
        frames += [(t, 0x201, rpdo), (t + 120e-6, 0x080, b""), (t + 240e-6, 0x181, tpdo)]
    # out of time order in the file, as a logger on canlink may write them
    frames[1], frames[2] = frames[2], frames[1]
    path = tmp_path / f"bus{suffix}"
    _write(path, frames)
    got = canload.read_log(path)
    assert [f.t for f in got] == sorted(f.t for f in got) and len(got) == 12
    load = canload.cycle_load(got, 1_000_000)
    per_cycle = (canlink.frame_bits(0x080, False, False, 0, b"")
                 + canlink.frame_bits(0x181, False, False, 6, tpdo)
                 + canlink.frame_bits(0x201, False, False, 6, rpdo))
    assert load.cycles == 3 and load.bits_max == per_cycle and load.bits_mean == per_cycle
    assert load.period_s == pytest.approx(1e-3, abs=1e-6)
    assert load.load_mean == pytest.approx(per_cycle / 1000, rel=1e-3)
    assert load.frames_per_cycle == 3


def test_cycle_load_needs_two_syncs(tmp_path: Path) -> None:
    path = tmp_path / "one.asc"
    _write(path, [(0.5, 0x080, b"")])
    with pytest.raises(ValueError, match="two SYNCs"):
        canload.cycle_load(canload.read_log(path), 1_000_000)
