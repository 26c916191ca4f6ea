"""The CLI end to end, with the setpoints checked in Python, independently
of the C planner and of the C checker: limits by differentiating the
CSV positions, arc geometry, error reporting, threaded mode, queue trace."""
from __future__ import annotations

import csv
import math
import subprocess
from pathlib import Path

import pytest

from motion_helpers import require

SCALE = 1_000_000.0  # increments per mm (1 nm)
PERIOD = 0.001
VMAX, AMAX, JMAX = 120.0, 1500.0, 60000.0

PROGRAM = """\
G21 G90 G17 F5000 (square, arcs, a helix and a dwell)
G1 X30
G1 Y20
G2 X50 Y20 I10 J0
G3 X50 Y40 R10
G1 X10 Y40 Z2
G4 P0.05
G18 G2 X0 Z2 I-5 K0
G17 G3 X0 Y40 Z5 I0 J-5 P2
G0 X0 Y0 Z0
M2
"""


def run_cli(args: list[str], program: str, tmp: Path) -> tuple[subprocess.CompletedProcess[str], list[dict[str, int]]]:
    b = require("host")
    src = tmp / "prog.gcode"
    src.write_text(program)
    out = tmp / "sp.csv"
    proc = subprocess.run(
        [str(b.binary("motion_cli")), "--csv", str(out), *args, str(src)],
        capture_output=True, text=True, timeout=120,
    )
    rows: list[dict[str, int]] = []
    if out.exists():
        with out.open() as f:
            rows = [{k: int(v) for k, v in r.items()} for r in csv.DictReader(f)]
    return proc, rows


def differences(rows: list[dict[str, int]], axis: str) -> tuple[float, float, float]:
    p = [r["p" + axis] / SCALE for r in rows]
    v = [(p[i] - p[i - 1]) / PERIOD for i in range(1, len(p))]
    a = [(v[i] - v[i - 1]) / PERIOD for i in range(1, len(v))]
    j = [(a[i] - a[i - 1]) / PERIOD for i in range(1, len(a))]
    return max(map(abs, v)), max(map(abs, a)), max(map(abs, j))


@pytest.mark.parametrize("jerk", [False, True], ids=["trapezoid", "jerk"])
def test_limits_from_differentiated_csv(tmp_path: Path, jerk: bool) -> None:
    args = ["--scale", str(SCALE), "--vmax", str(VMAX), "--amax", str(AMAX),
            "--jmax", str(JMAX), "--tol", "0.002"]
    if jerk:
        args.append("--jerk")
    proc, rows = run_cli(args, PROGRAM, tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert len(rows) > 500
    q = 1.0 / SCALE
    seen_a = 0.0
    for axis in "XYZ":
        vmax, amax, jmax = differences(rows, axis)
        assert vmax <= VMAX + q / PERIOD + 1e-9, (axis, vmax)
        assert amax <= AMAX + 2 * q / PERIOD**2 + 1e-6, (axis, amax)
        if jerk:
            assert jmax <= JMAX + 4 * q / PERIOD**3 + 1e-3, (axis, jmax)
        seen_a = max(seen_a, amax)
        # feed-forward never above the velocity limit
        assert max(abs(r["v" + axis]) for r in rows) <= VMAX * SCALE + 1
    # the check is not vacuous: the planner does use the acceleration
    assert seen_a > 0.3 * AMAX
    last = rows[-1]
    assert (last["pX"], last["pY"], last["pZ"]) == (0, 0, 0)
    assert last["status"] == 2  # MOTION_ST_DONE


def test_arc_geometry_from_csv(tmp_path: Path) -> None:
    tol = 0.002
    proc, rows = run_cli(["--scale", str(SCALE), "--tol", str(tol)],
                         "G1 X10 F3000\nG3 X10 Y0 I-10 J0\n", tmp_path)
    assert proc.returncode == 0, proc.stderr
    arc = [r for r in rows if r["line"] == 2]
    assert len(arc) > 100
    worst = max(abs(math.hypot(r["pX"] / SCALE, r["pY"] / SCALE) - 10.0) for r in arc)
    assert worst <= tol + 2e-6, worst
    ys = [r["pY"] / SCALE for r in arc]
    assert max(ys) == pytest.approx(10.0, abs=tol + 1e-3)
    assert min(ys) == pytest.approx(-10.0, abs=tol + 1e-3)


@pytest.mark.parametrize(
    "program,line,col,needle",
    [
        ("G1 X1 F100\nG1 X2 Y3 Q4\n", 2, 10, "unsupported word 'Q'"),
        ("G1 X1 F100\n\nG2 X5 Y0 F100\n", 3, 1, "centre"),
        ("G21\nG1 X1.2.3 F100\n", 2, 4, "decimal"),
        ("G1 X9999 F100\n", 1, 4, "travel"),
        ("(open comment\n", 1, 1, "unclosed comment"),
    ],
)
def test_errors_have_line_and_column(tmp_path: Path, program: str, line: int,
                                     col: int, needle: str) -> None:
    proc, rows = run_cli([], program, tmp_path)
    assert proc.returncode == 1
    src = tmp_path / "prog.gcode"
    assert f"{src}:{line}:{col}: error:" in proc.stderr, proc.stderr
    assert needle in proc.stderr
    assert rows and rows[-1]["status"] == 3  # MOTION_ST_FAULT, holding


def test_threaded_cli_realtime_and_trace(tmp_path: Path) -> None:
    trace = tmp_path / "queues.csv"
    proc, rows = run_cli(["--workers", "2", "--trace", str(trace)],
                         "G1 X20 Y10 F6000\nG2 X40 Y10 I10\nG0 X0 Y0\n", tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "underruns 0" in proc.stderr
    assert rows[-1]["pX"] == 0 and rows[-1]["pY"] == 0
    with trace.open() as f:
        header = f.readline().strip().split(",")
        samples = [line for line in f if line.strip()]
    assert header == ["t_us", "stream_bytes", "blocks", "segments", "planned",
                      "profiles", "setpoints"]
    assert len(samples) > 10


@pytest.mark.parametrize("args,why", [
    (["--axes", "9"], "--axes: '9' is not a number in [1, 6]"),
    (["--vmax", "12abc"], "--vmax: '12abc' is not a number"),
    (["--period-us", ""], "--period-us: '' is not a number"),
    (["--policy", "edf"], "--policy: 'edf' is neither hybrid nor fifo"),
    (["--chunk", "0"], "--chunk: '0' is not a number"),
], ids=["axes", "trailing", "empty", "policy", "chunk"])
def test_bad_option_values_refused(tmp_path: Path, args: list[str], why: str) -> None:
    """A value the CLI cannot use is refused with the option's name, before
    anything runs (atoi() used to take '12abc' as 12 and '' as 0)."""
    proc, rows = run_cli(args, PROGRAM, tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert why in proc.stderr
    assert rows == []
