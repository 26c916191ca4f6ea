"""bench/cycle/cycle_bench.py (issue 24, items 2 and 3): the least-squares
line, the rate table, the figures and their targets on synthetic sweeps,
the committed bench/results/cycle.json against its own points, and mypy
--strict. No QEMU run (the run itself: scripts/bench.sh cycle; the board
test of the long run: tests/robot/test_cycle_4khz_board.py)."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

from servoamp import bench

TOP = Path(__file__).resolve().parents[2]
SCRIPT = TOP / "bench" / "cycle" / "cycle_bench.py"


@pytest.fixture(scope="module")
def cb() -> ModuleType:
    spec = importlib.util.spec_from_file_location("cycle_bench", SCRIPT)
    assert spec and spec.loader
    mod = importlib.util.module_from_spec(spec)
    sys.modules["cycle_bench"] = mod
    spec.loader.exec_module(mod)
    return mod


def _point(axes: int, rate: int, missed: tuple[int, int] = (0, 0), work: float | None = None) -> dict[str, Any]:
    ins = {"rx": 1430, "ctrl": 200 + 440 * axes, "tx": 1280 + 10 * axes}
    ins["cycle"] = ins["rx"] + ins["ctrl"] + ins["tx"]
    return {"axes": axes, "rate_hz": rate, "period_us": round(1e6 / rate), "cycles_asked": 2000,
            "ok": missed == (0, 0),
            "linux": {"cycles": 2000, "missed": missed[0], "late": 0, "fb_torn": 0, "fb_invalid": 0,
                      "fb_stale": 0, "work_ns_mean": work if work is not None else 3100.0 + 180.0 * axes,
                      "wake_latency_histogram": {}},
            "servo": {"cycles": 2000, "missed": missed[1], "cmd_torn": 0, "cmd_invalid": 0, "cmd_stale": 0,
                      "axes": axes, "period_us": round(1e6 / rate), "cost_samples": 2100,
                      "instructions": {k: {"mean": v, "max": v + 10_000} for k, v in ins.items()},
                      "irq_entry_latency_ns_max": 10_000}}


def test_least_squares_line(cb: ModuleType) -> None:
    f = cb.fit([1.0, 2.0, 3.0, 4.0], [12.0, 22.0, 32.0, 42.0])
    assert f == {"slope": 10.0, "intercept": 2.0, "max_residual": 0.0, "points": 4}
    g = cb.fit([1.0, 2.0, 3.0], [1.0, 3.0, 2.0])
    assert g["slope"] == 0.5 and g["intercept"] == 1.0 and g["max_residual"] == 1.0
    with pytest.raises(ValueError):
        cb.fit([1.0], [1.0])


def test_fits_per_axis_from_the_points_of_one_rate(cb: ModuleType) -> None:
    pts = [_point(n, r) for n in range(1, 9) for r in (1000, 4000)]
    f = cb.fits(pts, 1000)
    assert f["axes"] == list(range(1, 9))
    assert f["servo_ctrl"]["slope"] == 440.0 and f["servo_ctrl"]["intercept"] == 200.0
    assert f["servo_cycle"]["slope"] == 450.0 and f["servo_cycle"]["intercept"] == 2910.0
    assert f["servo_rx_tx"]["slope"] == 10.0 and f["servo_rx_tx"]["intercept"] == 2710.0
    assert f["linux_work_ns"]["slope"] == 180.0 and f["linux_work_ns"]["intercept"] == 3100.0
    assert cb.fits(pts, 2000) == {}


def test_rate_table_is_the_highest_rate_with_every_lower_one_clean(cb: ModuleType) -> None:
    pts = [_point(1, r) for r in (1000, 2000, 4000, 8000)]
    pts += [_point(2, 1000), _point(2, 2000), _point(2, 4000, (1, 0)), _point(2, 8000)]
    pts += [_point(3, 1000, (0, 2)), _point(3, 2000)]
    pts += [{"axes": 4, "rate_hz": 1000, "period_us": 1000, "cycles_asked": 2000}]
    pts[-1]["refused"] = "SP_E_OVERLOAD"
    assert cb.rate_table(pts) == {"1": 8000, "2": 2000, "3": 0, "4": 0}


def test_axes_list(cb: ModuleType) -> None:
    assert cb.axes_list("1-8") == list(range(1, 9))
    assert cb.axes_list("1,4,8") == [1, 4, 8] and cb.axes_list("") == []
    with pytest.raises(Exception):
        cb.axes_list("0-9")


def test_figures_and_their_targets(cb: ModuleType) -> None:
    pts = [_point(n, r) for n in range(1, 9) for r in (1000, 2000, 4000, 8000)]
    long = _point(8, 4000)
    long["cycles_asked"] = 100_000
    long["linux"]["cycles"] = long["servo"]["cycles"] = 100_180
    mode = {"sweep": {"window_cycles": 2000, "points": pts, "fits": {"1000hz": cb.fits(pts, 1000),
                                                                      "4000hz": cb.fits(pts, 4000)},
                      "max_rate_hz": cb.rate_table(pts)},
            "long": long}
    figs = {f["name"]: f for f in cb.figures({"modes": {"virtual": mode}})}
    assert bench.validate({"benchmark": "cycle", "figures": list(figs.values())}) == []
    assert figs["fit_1khz_servo_cycle_instructions_per_axis"]["value"] == 450.0
    assert figs["fit_4khz_servo_ctrl_instructions_per_axis"]["value"] == 440.0
    assert figs["fit_1khz_linux_work_ns_per_axis"]["value"] == 180.0
    assert figs["sweep_1khz_8axes_servo_rx_tx_instructions"]["value"] == 1430 + 1360
    assert figs["sweep_4khz_8axes_servo_rx_instructions"]["value"] == 1430
    assert figs["max_rate_khz_8axes"]["value"] == 8.0 and figs["max_rate_khz_1axes"]["value"] == 8.0
    assert figs["long_4khz_8axes_missed_linux"]["value"] == 0
    assert figs["long_4khz_8axes_cycles"]["value"] == 100_180
    # each goal of issue 24 has its target in bench/targets.toml
    t = bench.load_targets()
    for name, target in (("fit_1khz_servo_cycle_instructions_per_axis", 1000),
                         ("fit_4khz_servo_ctrl_instructions_per_axis", 1000),
                         ("sweep_1khz_8axes_servo_rx_tx_instructions", 1000),
                         ("sweep_4khz_8axes_servo_rx_instructions", 1000),
                         ("virtual_250us_servo_rx_instructions", 1000),
                         ("long_4khz_8axes_missed_linux", 0), ("long_4khz_8axes_missed_servo", 0),
                         ("long_4khz_8axes_cycles", 100_000), ("max_rate_khz_8axes", 4)):
        found = bench.find_target(t, "cycle", name)
        assert found is not None and found.value == target, name
    assert "issue 24" in (bench.find_target(t, "cycle", "long_4khz_8axes_missed_servo") or
                          bench.Target(0, None, "")).source


def test_committed_results_agree_with_their_points(cb: ModuleType) -> None:
    _agree(cb, TOP / "bench" / "results" / "cycle.json")


def test_committed_zynqmp_results_agree_with_their_points(cb: ModuleType) -> None:
    path = TOP / "bench" / "results" / "cycle-zynqmp_qemu.json"
    doc = json.loads(path.read_text())
    assert doc["board"] == "zynqmp_qemu"
    assert doc["timebase"]["ticks_per_us"] == 1000 and doc["timebase"]["ns_per_instruction"] == 1
    _agree(cb, path)


def _agree(cb: ModuleType, path: Path) -> None:
    doc = json.loads(path.read_text())
    assert bench.validate(doc) == []
    mode = doc["modes"]["virtual"]
    if "sweep" not in mode:
        pytest.skip("results from before the sweep (issue 24)")
    sw = mode["sweep"]
    assert sorted({p["axes"] for p in sw["points"]}) == list(range(1, 9))
    assert sw["max_rate_hz"] == cb.rate_table(sw["points"])
    for key, f in sw["fits"].items():
        assert f == cb.fits(sw["points"], int(key[:-2]))
    figs = {f["name"]: f["value"] for f in doc["figures"]}
    for p in sw["points"]:
        if "servo" in p:
            assert p["servo"]["axes"] == p["axes"] and p["servo"]["period_us"] == p["period_us"]
            assert p["linux"]["cycles"] >= p["cycles_asked"] and p["servo"]["cycles"] >= p["cycles_asked"] - 1
    lg = mode["long"]
    assert lg["servo"]["axes"] == lg["axes"] and lg["servo"]["period_us"] == lg["period_us"]
    k = f"long_{lg['rate_hz'] / 1000:g}khz_{lg['axes']}axes"
    assert figs[f"{k}_missed_linux"] == lg["linux"]["missed"] and figs[f"{k}_missed_servo"] == lg["servo"]["missed"]


def test_time_base_and_instruction_clock_from_the_boards_data(cb: ModuleType) -> None:
    """Ticks of the servo's time base to instructions from the servo
    devicetree (BOARD_TIMEBASE_TICKS_PER_US, as rpu_app's generator
    derives it) and board.yaml's -icount shift: the A9's global timer at
    100 MHz (a tick is 10 instructions), the R5's PMCCNTR at the 1 GHz
    QEMU counts (a tick is one)."""
    from servoamp import qemu
    a9 = cb.TimeBase.of(qemu.Board.load("zynq7000_qemu"))
    r5 = cb.TimeBase.of(qemu.Board.load("zynqmp_qemu"))
    assert (a9.ticks_per_us, a9.ns_per_instruction) == (100, 1)
    assert (r5.ticks_per_us, r5.ns_per_instruction) == (1000, 1)
    assert a9.instructions(53) == 530 and r5.instructions(530) == 530
    assert a9.us(250) == 2.5 and r5.us(2500) == 2.5
    assert cb.TimeBase(1000, 2).instructions(530) == 265   # shift=1: 2 ns an instruction


def _window(ticks_per_us: int, rx: int) -> dict[str, Any]:
    cost = {p: {"mean": rx, "max": 2 * rx} for p in ("rx", "ctrl", "tx", "cycle")}
    return {"guest_seconds": 1,
            "linux": {"cycles": 1000, "missed": 0, "wake_latency_ns_since_start": {"min": 1, "mean": 2, "max": 3}},
            "servo": {"cycles": 1000, "missed": 0, "axes": 4, "irq_entry_latency_ns_max_since_start": 1000,
                      "ticks_per_us": ticks_per_us, "cost_ticks_since_start": cost}}


def test_window_figures_convert_each_boards_ticks(cb: ModuleType) -> None:
    a9 = {f["name"]: f["value"] for f in cb.figures({"modes": {"virtual": {"1000us": _window(100, 53)}}})}
    r5 = {f["name"]: f["value"] for f in cb.figures({"modes": {"virtual": {"1000us": _window(1000, 530)}},
                                                    "timebase": {"ns_per_instruction": 1}})}
    for figs in (a9, r5):
        assert figs["virtual_1000us_servo_rx_instructions"] == 530
        assert figs["virtual_1000us_servo_handler_max"] == 1.06    # us: 1060 ns
    # results from before --board: A9 ticks of 10 ns under their old key
    old = _window(100, 53)
    old["servo"]["cost_ticks_10ns_since_start"] = old["servo"].pop("cost_ticks_since_start")
    del old["servo"]["ticks_per_us"]
    assert {f["name"]: f["value"] for f in cb.figures({"modes": {"virtual": {"1000us": old}}})} == a9


def test_cycle_bench_is_mypy_strict() -> None:
    mypy = Path(sys.executable).parent / "mypy"
    p = subprocess.run([str(mypy), "--strict", str(SCRIPT)], capture_output=True, text=True, timeout=300,
                       cwd=TOP, env={"MYPYPATH": str(TOP / "python"), "PATH": "/usr/bin:/bin"})
    assert p.returncode == 0, p.stdout + p.stderr
