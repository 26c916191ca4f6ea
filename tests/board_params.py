"""The boards a board suite runs on, and their images once per session.

A board test module parametrizes its boot fixture by :data:`BOARDS` (the
values are the boards' names: tests/conftest.py gives each test its board
for ``--board``), one boot per board per module, and takes the board and
its images from :func:`board_images`."""

from __future__ import annotations

import sys
import time
from pathlib import Path

from servoamp import qemu

REPO = Path(__file__).resolve().parents[1]


def board_names() -> list[str]:
    """Every board: the folders of boards/ with a board.yaml."""
    return sorted(p.parent.name for p in (REPO / "boards").glob("*/board.yaml"))


BOARDS = board_names()
_IMAGES: dict[str, qemu.Images] = {}


def board_images(name: str) -> tuple[qemu.Board, qemu.Images]:
    """A board and its images, built (or taken from the caches) once per
    session."""
    board = qemu.Board.load(name)
    if name not in _IMAGES:
        t0 = time.monotonic()
        _IMAGES[name] = qemu.prepare_images(board)
        print(f"\n[{name}] images ready in {time.monotonic() - t0:.1f} s", file=sys.stderr)
    return board, _IMAGES[name]
