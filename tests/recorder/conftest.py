from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from recorder_helpers import TOP, make


@pytest.fixture(scope="session")
def feed_bin() -> Path:
    return make("none") / "telem_feed"


@pytest.fixture(scope="session")
def node_ready() -> None:
    if shutil.which("node") is None:
        pytest.skip("node is not installed (scripts/bootstrap.sh installs the reader's modules)")
    if not (TOP / "tools" / "mcap-verify" / "node_modules" / "@mcap" / "core").is_dir():
        pytest.fail("tools/mcap-verify/node_modules missing: run scripts/bootstrap.sh")
