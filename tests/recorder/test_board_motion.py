"""The motion pipeline drives the emulated controller (one QEMU boot).

servod runs G-code through libmotion (``ampctl run``): the squares-and-circles program
(examples/seed004_squares_circles.nc: a 20 mm square with G1, a 10 mm circle
with G2 then G3, 1500-3000 mm/min) runs end to end while
``servoamp record`` records every cycle; servod's own path-error figures
(``ampctl stats``: motion.*) are checked against bounds derived from the
plant and its loops, the final position against the program's end point,
and the recording is plotted (XY path). A malformed program is refused with
line and column and the controller holds its position; ``ampctl stop``
decelerates along the path and holds.

Bounds (default parameters: pos_kp 60/s, PI velocity loop 0.5 A.s/rad and
20 A/rad, J 1e-4 kg.m2, kt 0.1 N.m/A, 10000 inc/rev; 1 inc = 1 um):

* path (contour) error max <= 60 um. A host model of the same loops
  (sub-steps, the same feed-forward) fed with the pipeline's setpoints gives
  16 um without missed cycles and 22 um with 5 % of the servo's cycles lost;
  a lost servo cycle makes the next coarse step twice as long (33-50 um at
  2000-3000 mm/min). 60 um leaves room for the TCG host's bursts of misses.
  When more than 5 % of the servo's command cycles were lost (a loaded host,
  guest time on the host clock), the bounds' premise does not hold: the
  figures are reported, and only the loss-independent relations checked.
* following error (XY, commanded setpoint of the same command sequence vs
  actual) max <= 300 um: 27 um modelled without misses, 119 um with 5 %;
  every missed servo cycle adds one coarse step of lag.
* final position = the program's end point (0, 0, 0) within 3 inc after
  0.5 s at rest: the velocity loop's integrator removes the static error
  (no Coulomb friction in the plant), the rest is the feedback's rounding.

On both boards (the fixture is parametrized by board, one boot each): the
same bounds on the R5 as on the A9 (the same plant and loops; the cycles
are guest time on both).
"""

from __future__ import annotations

import math
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from board_params import BOARDS, board_images
from servoamp import mcapio, netboard, plot, qemu
from servoamp.record import RecordResult, record

pytestmark = pytest.mark.board

SQUARES_CIRCLES = "/usr/share/servoamp/examples/seed004_squares_circles.nc"
END = (0, 0, 0)                 # the program's end point, increments
PATH_ERR_MAX_UM = 60.0
FOLLOW_ERR_MAX_UM = 300.0
END_TOL_INC = 3
RECORD_MAX_S = 120.0            # upper bound; the recording stops when the program is done


def _wait_state(cb: netboard.ControllerBoard, states: set[str], timeout: float) -> dict[str, str]:
    return cb.wait_status(lambda st: st.get("program.state") in states, timeout, raise_on_timeout=False)


def _ints(s: str) -> list[int]:
    return [int(x) for x in s.split(",")]


@pytest.fixture(scope="module", params=BOARDS)
def run(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    board, images = board_images(request.param)
    tmp = tmp_path_factory.mktemp(f"board_motion_{board.name}")
    out: dict[str, Any] = {"path": tmp / "motion.mcap", "tmp": tmp, "board": board.name}
    with netboard.ControllerBoard(board, images) as cb:
        t0 = time.monotonic()
        cb.start_servod()
        cb.start_firmware()
        cb.wait_telemetry()
        cb.ampctl("param set wd_limit 50")   # as the other board suites: TCG hiccups
        cb.ampctl("resume", expected_rc=None)
        out["idle"] = cb.status()

        # 1. a malformed program: refused with line and column, the axes hold
        cb.sh("printf 'G21 G90\\nG1 X1 Y1 F1000\\nG1 X2 Q5\\n' > /tmp/bad.nc")
        out["bad_rc"], out["bad_out"] = cb.sh_rc("ampctl run /tmp/bad.nc 2>&1", timeout=30)
        out["bad_st1"] = cb.status()
        time.sleep(0.5)
        out["bad_st2"] = cb.status()

        # 2. the squares-and-circles program, recorded
        # recorded until the program is done (its length in host time grows
        # with the cycles the host makes the guest miss), not for a fixed time
        box: dict[str, RecordResult] = {}
        stop_rec = threading.Event()
        th = threading.Thread(target=lambda: box.update(
            r=record("127.0.0.1", cb.host_port, out["path"], RECORD_MAX_S, stop=stop_rec,
                     token=cb.token)))
        th.start()
        time.sleep(0.5)
        out["run_rc"], out["run_out"] = cb.sh_rc(f"ampctl run {SQUARES_CIRCLES} 2>&1", timeout=30)
        out["busy_rc"], out["busy_out"] = cb.sh_rc(f"ampctl run {SQUARES_CIRCLES} 2>&1", timeout=30)
        out["done_st"] = _wait_state(cb, {"done", "fault", "stopped"}, 30)
        out["t_done"] = time.monotonic() - t0
        time.sleep(0.5)
        out["end_st"] = cb.status()
        out["stats"] = cb.stats()
        stop_rec.set()
        th.join(timeout=30)
        assert not th.is_alive()
        out["res"] = box["r"]

        # 3. ampctl stop in the middle of the square: decelerate along the path, hold
        cb.ampctl(f"run {SQUARES_CIRCLES}")
        time.sleep(1.5)
        out["before_stop"] = cb.status()
        out["stop_out"] = cb.ampctl("stop")
        out["stop_st"] = _wait_state(cb, {"stopped", "done", "fault"}, 10)
        time.sleep(0.5)
        out["stop_st2"] = cb.status()
        out["stop_stats"] = cb.stats()
        out["servod_log"] = cb.sh(f"cat {netboard.SERVOD_LOG}")
        out["board_s"] = time.monotonic() - t0
    return out


def test_malformed_program_refused_and_holding(run: dict[str, Any]) -> None:
    assert run["idle"]["program.mode"] == "sine"
    print("\n" + run["bad_out"])
    assert run["bad_rc"] == 9, run["bad_out"]
    assert "/tmp/bad.nc:3:" in run["bad_out"] and "Q" in run["bad_out"]
    col = run["bad_out"].split("/tmp/bad.nc:3:")[1].split(":")[0]
    assert int(col) == 7, run["bad_out"]      # 'Q' of "G1 X2 Q5"
    for st in (run["bad_st1"], run["bad_st2"]):
        assert st["program.mode"] == "hold" and st["program.state"] == "refused"
        assert "/tmp/bad.nc:3:7" in st["program.error"]
    # nothing moves: the same command, the axes where they were
    assert run["bad_st1"]["program.cmd_inc"] == run["bad_st2"]["program.cmd_inc"]
    c = _ints(run["bad_st2"]["program.cmd_inc"])
    a1, a2 = _ints(run["bad_st1"]["program.act_inc"]), _ints(run["bad_st2"]["program.act_inc"])
    assert all(abs(x - y) <= 3 for x, y in zip(a1, a2)), (a1, a2)
    assert all(abs(x - y) <= 3 for x, y in zip(a2, c)), (a2, c)


def test_squares_circles_runs_to_the_end_point(run: dict[str, Any]) -> None:
    print("\n" + run["run_out"])
    assert run["run_rc"] == 0, run["run_out"]
    assert "checked" in run["run_out"] and "end X0.0000 Y0.0000 Z0.0000" in run["run_out"]
    assert run["busy_rc"] == 10, run["busy_out"]   # one program at a time
    st = run["done_st"]
    assert st["program.state"] == "done", st
    assert st["program.mode"] == "hold"
    assert "program.error" not in st
    assert int(st["program.lines"]) == 19 and int(st["program.blocks"]) >= 9
    # every planned setpoint went to the servo
    assert int(st["program.setpoints"]) == int(st["program.planned_setpoints"])
    end = run["end_st"]
    assert _ints(end["program.cmd_inc"]) == list(END)
    act = _ints(end["program.act_inc"])
    assert all(abs(a - e) <= END_TOL_INC for a, e in zip(act, END)), act


def test_path_error_within_bounds(run: dict[str, Any]) -> None:
    s, st = run["stats"], run["done_st"]
    print(f"\nsquares and circles on {run['board']}: path error max {s['motion.path_err.max_um']} um "
          f"(line {s['motion.path_err.max_line']}), rms {s['motion.path_err.rms_um']} um; "
          f"following error max {s['motion.follow_err.max_um']} um "
          f"(line {s['motion.follow_err.max_line']}), rms {s['motion.follow_err.rms_um']} um; "
          f"per axis {s['motion.follow_err.axis_max_inc']} inc; samples {s['motion.samples']}, "
          f"servo command skips {s['motion.cmd_skips']}, underruns {s['motion.underruns']}, "
          f"alignment mismatches {s['motion.align_mismatch']}; "
          f"servod missed_irq {s['linux.missed_irq']}, servo missed {s.get('servo.missed')}; "
          f"board {run['board_s']:.1f} s")
    assert int(s["motion.samples"]) > 0
    # the feedback's command sequence gives the alignment: the servo's own
    # following error (p1 - actual) is the distance servod computes
    assert int(s["motion.align_mismatch"]) == 0
    assert int(s["motion.underruns"]) == 0
    # the contour error never exceeds the distance to the commanded point
    assert float(s["motion.path_err.max_um"]) <= float(s["motion.follow_err.max_um"])
    assert float(s["motion.path_err.rms_um"]) <= float(s["motion.follow_err.rms_um"])
    if qemu.default_clock() == "virtual":
        # host load cannot cost the guest a cycle: the bounds always apply
        assert int(s["linux.missed_irq"]) == 0 and int(s["motion.cmd_skips"]) == 0
        assert _within_model(s)
    if _within_model(s):
        assert int(s["motion.samples"]) > 0.8 * int(st["program.planned_setpoints"])
        assert float(s["motion.path_err.max_um"]) <= PATH_ERR_MAX_UM
        assert float(s["motion.follow_err.max_um"]) <= FOLLOW_ERR_MAX_UM


def _within_model(s: dict[str, str]) -> bool:
    """The error bounds (module docstring) are derived for at most 5 % of
    the servo's command cycles lost. On the host clock a loaded host can
    make the emulated board lose more (each loss is counted:
    motion.cmd_skips); those runs are reported, not judged by the bounds."""
    skips, samples = int(s["motion.cmd_skips"]), max(1, int(s["motion.samples"]))
    if skips <= 0.05 * samples:
        return True
    print(f"\n{skips} of {samples} servo command cycles lost ({100.0 * skips / samples:.1f} % > 5 %): "
          f"path error {s['motion.path_err.max_um']} um, following error {s['motion.follow_err.max_um']} um "
          "reported, not bounded (the host was too busy for the model's premise)")
    return False


def test_stop_decelerates_and_holds(run: dict[str, Any]) -> None:
    b, st, st2 = run["before_stop"], run["stop_st"], run["stop_st2"]
    assert b["program.state"] == "running", b
    assert st["program.state"] == "stopped" and st["program.mode"] == "hold", st
    assert st["program.cmd_inc"] == st2["program.cmd_inc"]
    c, a = _ints(st2["program.cmd_inc"]), _ints(st2["program.act_inc"])
    assert all(abs(x - y) <= END_TOL_INC for x, y in zip(c, a)), (c, a)
    # it stopped on the path (the square's first sides), not at the end point
    assert c[:2] != [0, 0]
    if _within_model(run["stop_stats"]):
        assert float(run["stop_stats"]["motion.path_err.max_um"]) <= PATH_ERR_MAX_UM


def test_recording_shows_the_square_and_the_circle(run: dict[str, Any]) -> None:
    res: RecordResult = run["res"]
    cx, cy, ax, ay = [], [], [], []
    per: dict[int, dict[int, Any]] = {}
    for _tp, _t, m in mcapio.iter_json(run["path"], [mcapio.axis_topic(0), mcapio.axis_topic(1)]):
        per.setdefault(m["cycle"], {})[m["axis"]] = m
    for c in sorted(per):
        if len(per[c]) == 2:
            cx.append(per[c][0]["command"]["target_pos"])
            cy.append(per[c][1]["command"]["target_pos"])
            ax.append(per[c][0]["feedback"]["actual_pos"])
            ay.append(per[c][1]["feedback"]["actual_pos"])
    # every setpoint of the program is on record (plus the approach and the rest)
    assert res.cycles >= int(run["done_st"]["program.planned_setpoints"]), res.cycles
    # The program's first block moves from wherever the axes hold (where the
    # sine left them when the malformed program was refused: anywhere) to
    # the origin; the shape is what follows the first arrival there.
    i0 = next((i for i, (x, y) in enumerate(zip(cx, cy)) if math.hypot(x, y) <= 2), None)
    assert i0 is not None, "the commanded path never reaches the origin"
    cx, cy, ax, ay = cx[i0:], cy[i0:], ax[i0:], ay[i0:]
    # the square's corners and the circle's extremes are on record
    for corner in ((20000, 0), (20000, 20000), (0, 20000)):
        assert min(math.hypot(x - corner[0], y - corner[1]) for x, y in zip(cx, cy)) <= 2, corner
    # the circles: G2 at 25 mm/s (~1260 cycles) and G3 at 50 mm/s (~630 cycles)
    # on r = 5 mm within the chord tolerance (1 um) and the rounding
    on_circle = sum(1 for x, y in zip(cx, cy) if abs(math.hypot(x - 10000, y - 10000) - 5000) <= 2)
    assert on_circle > 1500, on_circle
    assert abs(max(cx) - 20000) <= 2 and abs(min(cy)) <= 2 and max(ay) > 19900
    files = plot.plot(run["path"], run["tmp"] / "plots")
    xy = next(f for f in files if f.name == "xy_path.png")
    assert xy.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and xy.stat().st_size > 10_000
    dest = qemu.REPO / "build" / "test-artifacts"
    dest.mkdir(parents=True, exist_ok=True)
    png = dest / f"squares_circles_xy_path-{run['board']}.png"
    png.write_bytes(xy.read_bytes())
    print(f"\nXY plot: {png}")
