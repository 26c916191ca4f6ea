# SPDX-License-Identifier: MIT
"""Fixtures of the fieldbus tests."""

from __future__ import annotations

from pathlib import Path
from typing import Iterator

import pytest

from fieldbus_helpers import Peer


@pytest.fixture
def peer(tmp_path: Path) -> Iterator[Peer]:
    """QEMU's side of a canlink socket, ``tmp_path / "can.sock"``."""
    p = Peer(tmp_path / "can.sock")
    yield p
    p.srv.close()
