# SPDX-License-Identifier: MIT
"""Fixtures for rpu_app tests: one build of both firmware variants per test
session, into the session's temporary directory (never into build/, which
other tools use concurrently). What the tests share besides fixtures is in
rpu_common.py."""
from __future__ import annotations

import shutil
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

from rpu_common import BOARD, _make, parse_board_config  # noqa: E402

@pytest.fixture(scope="session")
def toolchain():
    if not shutil.which("arm-none-eabi-gcc"):
        pytest.skip("arm-none-eabi-gcc missing: run scripts/bootstrap.sh")


@pytest.fixture(scope="session")
def rpu_build(tmp_path_factory, toolchain) -> Path:
    build = tmp_path_factory.mktemp("rpu_app") / BOARD
    r = _make(build)
    assert r.returncode == 0, f"make failed:\n{r.stdout}\n{r.stderr}"
    for name in ("servo.elf", "servo-norsc.elf", "qemu-stub.elf", "board_config.h", "board_memory.ld"):
        assert (build / name).is_file(), name
    return build


@pytest.fixture(scope="session")
def board_cfg(rpu_build) -> dict[str, int]:
    return parse_board_config(rpu_build / "board_config.h")
