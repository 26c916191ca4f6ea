"""Run each Robot Framework suite of tests/robot on the emulated board (one
QEMU boot per suite) and require it to pass. Reports: build/robot/<suite>/."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from servoamp import qemu

REPO = Path(__file__).resolve().parents[2]
SUITES = sorted((REPO / "tests" / "robot").glob("[0-9][0-9]_*.robot"))


@pytest.mark.board
@pytest.mark.parametrize("suite", SUITES, ids=[s.stem for s in SUITES])
def test_robot_suite(suite: Path, images: qemu.Images) -> None:
    out = REPO / "build" / "robot" / suite.stem
    robot = Path(sys.executable).with_name("robot")
    cmd = [str(robot), "--pythonpath", str(REPO / "python"), "--outputdir", str(out),
           "--console", "verbose", str(suite)]
    res = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=900)
    print(res.stdout[-6000:])
    assert res.returncode == 0, (
        f"robot suite {suite.name} failed (rc={res.returncode}); log: {out}/log.html\n"
        f"{res.stdout[-4000:]}\n{res.stderr[-2000:]}"
    )
