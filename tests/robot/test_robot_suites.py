"""Run each Robot Framework suite on its emulated board (one QEMU boot per
suite) and require it to pass: tests/robot/*.robot on zynq7000_qemu,
tests/robot/zynqmp/*.robot on zynqmp_qemu. Reports:
build/robot/<suite>/ (zynqmp_<suite>/ for the ZynqMP's)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from servoamp import qemu

REPO = Path(__file__).resolve().parents[2]
ROBOT = REPO / "tests" / "robot"
# (suite, the board it runs on, its report folder under build/robot)
SUITES = [(s, "zynq7000_qemu", s.stem) for s in sorted(ROBOT.glob("[0-9][0-9]_*.robot"))] + \
    [(s, "zynqmp_qemu", "zynqmp_" + s.stem) for s in sorted((ROBOT / "zynqmp").glob("[0-9][0-9]_*.robot"))]


@pytest.mark.board
@pytest.mark.parametrize("suite,board_name,report", SUITES, ids=[r for _, _, r in SUITES])
def test_robot_suite(suite: Path, board_name: str, report: str, request: pytest.FixtureRequest) -> None:
    # the board's images, built (or taken from the caches) before the timeout starts
    imgs: qemu.Images = request.getfixturevalue("images" if board_name == "zynq7000_qemu" else "zynqmp_images")
    assert imgs.firmware
    out = REPO / "build" / "robot" / report
    robot = Path(sys.executable).with_name("robot")
    cmd = [str(robot), "--pythonpath", str(REPO / "python"), "--outputdir", str(out),
           "--console", "verbose", str(suite)]
    res = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=900)
    print(res.stdout[-6000:])
    assert res.returncode == 0, (
        f"robot suite {suite.name} failed (rc={res.returncode}); log: {out}/log.html\n"
        f"{res.stdout[-4000:]}\n{res.stderr[-2000:]}"
    )
