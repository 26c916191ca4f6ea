"""bench/fieldbus/can_bench.py (issue 22's bus load and axes x rate): its
arithmetic on a synthetic bus, the committed bench/results/fieldbus.json
against its own points, and mypy --strict. No QEMU run and no figure
asserted (the run itself: scripts/bench.sh fieldbus, bench/README.md)."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import pytest

from servoamp import bench, canlink

TOP = Path(__file__).resolve().parents[2]
SCRIPT = TOP / "bench" / "fieldbus" / "can_bench.py"


@pytest.fixture(scope="module")
def cb() -> ModuleType:
    spec = importlib.util.spec_from_file_location("can_bench", SCRIPT)
    assert spec and spec.loader
    mod = importlib.util.module_from_spec(spec)
    sys.modules["can_bench"] = mod  # dataclasses look their module up
    spec.loader.exec_module(mod)
    return mod


def test_analytic_bits_match_the_firmware_generator(cb: ModuleType) -> None:
    # gen_board_header.py's worst case: SYNC 55, a 6-byte PDO 115 bit
    # times, a heartbeat 65 per drive (BOARD_CANn_LOAD_PERMILLE 645 for two
    # drives at 1 kHz with the master's time stamp off, as the bench's
    # overlays have it; tests/rpu_app/test_rpu_devicetree.py)
    assert cb.analytic_bits(2) == (47 + 4 * 95, 645)
    assert cb.analytic_bits(3)[1] == 940 and cb.analytic_bits(4)[1] == 1235
    assert "can-time-stamp-ms = <0>;" in cb.overlay(1000, {0: 2})
    sync = canlink.frame_bits(0x080, False, False, 0, b"")
    assert 47 <= sync <= cb.bits_worst(0)


def test_bus_load_sums_frame_bits_from_sync_to_sync(cb: ModuleType) -> None:
    pdo = canlink.frame_bits(0x201, False, False, 6, bytes(6))
    tpdo = canlink.frame_bits(0x181, False, False, 6, bytes(6))
    sync = canlink.frame_bits(0x080, False, False, 0, b"")
    hb = canlink.frame_bits(0x701, False, False, 1, b"\x05")
    frames = []
    for k in range(10):
        t = k * 1_000_000
        frames += [(t + 100_000, 0x201, pdo), (t + 200_000, 0x080, sync), (t + 300_000, 0x181, tpdo)]
    frames.append((5_400_000, 0x701, hb))
    r = cb.bus_load(frames, 0, 10_000_000, 1000)
    assert r["cycles"] == 9 and r["bits_min"] == pdo + sync + tpdo and r["bits_max"] == pdo + sync + tpdo + hb
    assert r["bits_per_cycle_by_kind"]["heartbeat"] == pytest.approx(hb / 9, abs=0.1)
    assert r["load_max_pct"] == pytest.approx((pdo + sync + tpdo + hb) / 10, abs=0.01)
    assert r["sync_gap_ns"] == {"min": 1_000_000, "max": 1_000_000, "mean": 1_000_000}


def test_overlay_puts_drives_on_both_buses(cb: ModuleType) -> None:
    text = cb.overlay(500, {0: 1, 1: 6})
    assert "cycle-period-us = <500>;" in text and text.count('servoamp,backend = "can"') == 7
    assert "axis@6 {" in text and "reg = <6>;" in text and "&axis3 {" in text
    assert cb.boots_for([1, 2, 3, 4]) == [{0: 3, 1: 1}, {0: 2}, {0: 4}]  # at most 4 axes in use


def test_committed_results_agree_with_their_points() -> None:
    path = TOP / "bench" / "results" / "fieldbus.json"
    if not path.exists():
        pytest.skip("no bench/results/fieldbus.json yet")
    doc = json.loads(path.read_text())
    assert bench.validate(doc) == []
    figs = {f["name"]: f["value"] for f in doc["figures"]}
    for p in doc["points"]:
        if p.get("refused"):
            assert not p["pass"]
            continue
        assert p["pass"] == (p["stats"]["sync_missed"] == 0 and p["nodes_op"] == p["drives"])
        tag = f"{p['drives']}drives_{p['rate_hz'] // 1000}khz"
        assert figs[f"sync_missed_{tag}"] == p["stats"]["sync_missed"]
    best = max((p["drives"] * p["rate_hz"] for p in doc["points"] if p["pass"]), default=0)
    assert figs["max_axes_x_rate_per_bus"] == best


def test_can_bench_is_mypy_strict() -> None:
    mypy = Path(sys.executable).parent / "mypy"
    p = subprocess.run([str(mypy), "--strict", str(SCRIPT)], capture_output=True, text=True, timeout=300,
                       cwd=TOP, env={"MYPYPATH": str(TOP / "python"), "PATH": "/usr/bin:/bin"})
    assert p.returncode == 0, p.stdout + p.stderr
