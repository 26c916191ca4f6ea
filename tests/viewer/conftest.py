from __future__ import annotations

import shutil
import sys
from pathlib import Path

import pytest

# the recorder tests' helpers (telem_feed, ports), shared rather than copied
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "recorder"))

from recorder_helpers import TOP, make  # noqa: E402

VIEWER = TOP / "tools" / "viewer"
CHROMIUM = Path("/usr/bin/chromium")


@pytest.fixture(scope="session")
def feed_bin() -> Path:
    return make("none") / "telem_feed"


@pytest.fixture(scope="session")
def viewer_ready() -> None:
    if shutil.which("node") is None:
        pytest.skip("node is not installed (scripts/bootstrap.sh installs the viewer's modules)")
    if not (VIEWER / "node_modules" / "@foxglove" / "studio-base" / "assets" / "index.js").is_file():
        pytest.fail("tools/viewer/node_modules missing: run scripts/bootstrap.sh")
    if not CHROMIUM.exists():
        pytest.fail(f"{CHROMIUM} missing (Debian's chromium): run scripts/bootstrap.sh")
