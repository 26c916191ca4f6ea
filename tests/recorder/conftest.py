from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from recorder_helpers import TOP, make

# Subprocesses (`python -m servoamp.cli ...`) run this tree's servoamp, not
# the one the shared virtualenv was installed from.
os.environ["PYTHONPATH"] = os.pathsep.join(
    [str(TOP / "python")] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p])


@pytest.fixture(scope="session")
def feed_bin() -> Path:
    return make("none") / "telem_feed"


@pytest.fixture(scope="session")
def node_ready() -> None:
    if shutil.which("node") is None:
        pytest.skip("node is not installed (scripts/bootstrap.sh installs the reader's modules)")
    if not (TOP / "tools" / "mcap-verify" / "node_modules" / "@mcap" / "core").is_dir():
        pytest.fail("tools/mcap-verify/node_modules missing: run scripts/bootstrap.sh")
