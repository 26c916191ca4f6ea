"""Every test uses this tree's Python package (python/servoamp), not one
installed elsewhere in the environment: put it first on the path before any
test module imports ``servoamp``."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "python"))
