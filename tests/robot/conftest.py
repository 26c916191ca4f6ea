"""Shared fixtures of the board tests: the images are built (or taken from
the caches) once per pytest session, before any QEMU boot, so that a cold
kernel build is not counted against a suite's timeout."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "python"))

from board_params import board_images  # noqa: E402
from servoamp import qemu  # noqa: E402


@pytest.fixture(scope="session")
def board() -> qemu.Board:
    return qemu.Board.load("zynq7000_qemu")


@pytest.fixture(scope="session")
def images(board: qemu.Board) -> qemu.Images:
    return board_images(board.name)[1]


@pytest.fixture(scope="session")
def zynqmp_images() -> qemu.Images:
    """The zynqmp_qemu board's images (TF-A, BL33 stub, the arm64 RT kernel,
    initramfs with the R5 test firmware, DTB), built or cached once."""
    return board_images("zynqmp_qemu")[1]
