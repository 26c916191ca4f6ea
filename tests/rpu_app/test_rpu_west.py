# SPDX-License-Identifier: MIT
"""`west build` (scripts/west_commands/build.py): in a west workspace made
with `west init -l` from a copy of this repository, and directly, including
the pristine policy and the refusal to wipe foreign directories."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from rpu_common import BOARD, REPO

BUILD_PY = REPO / "scripts" / "west_commands" / "build.py"
IGNORE = shutil.ignore_patterns(".venv", "build", ".git", ".west", "__pycache__", "*.o", "*.d", "output")


def west_bin():
    w = Path(sys.executable).parent / "west"
    return str(w) if w.exists() else shutil.which("west")


def run(cmd, cwd, **kw):
    env = dict(os.environ, PATH=f"{Path(sys.executable).parent}:{os.environ.get('PATH', '')}")
    return subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, env=env, **kw)


@pytest.fixture(scope="module")
def workspace(tmp_path_factory, toolchain):
    if not west_bin():
        pytest.skip("west missing: run scripts/bootstrap.sh")
    top = tmp_path_factory.mktemp("westws")
    repo = top / "servoamp"
    shutil.copytree(REPO, repo, ignore=IGNORE, symlinks=True)
    r = run([west_bin(), "init", "-l", "."], cwd=repo)
    assert r.returncode == 0, r.stdout + r.stderr
    assert (top / ".west" / "config").is_file()
    return repo


def test_west_lists_build(workspace):
    r = run([west_bin(), "help"], cwd=workspace)
    assert r.returncode == 0, r.stderr
    assert "build:" in r.stdout


def test_west_build_default_dir(workspace):
    r = run([west_bin(), "build", "-b", BOARD, "rpu_app"], cwd=workspace)
    assert r.returncode == 0, r.stdout + r.stderr
    out = workspace / "build" / "rpu_app" / BOARD
    assert (out / "servo.elf").is_file() and (out / "servo-norsc.elf").is_file()
    assert json.loads((out / ".servoamp-build.json").read_text())["board"] == BOARD
    # second run: nothing to rebuild
    r = run([west_bin(), "build", "-b", BOARD, "rpu_app", "-v"], cwd=workspace)
    assert r.returncode == 0 and "arm-none-eabi-gcc" not in r.stdout, r.stdout


def test_west_build_dir_and_pristine(workspace, tmp_path):
    d = tmp_path / "b"
    r = run([west_bin(), "build", "-b", BOARD, "-d", str(d), "rpu_app", "--", "AMP_LIB=0"], cwd=workspace)
    assert r.returncode == 0, r.stdout + r.stderr
    junk = d / "junk.txt"
    junk.write_text("x")
    r = run([west_bin(), "build", "-p", "never", "-d", str(d), "rpu_app", "--", "AMP_LIB=0"], cwd=workspace)
    assert r.returncode == 0 and junk.exists(), "board remembered, -p never keeps files"
    r = run([west_bin(), "build", "-p", "always", "-b", BOARD, "-d", str(d), "rpu_app", "--", "AMP_LIB=0"],
            cwd=workspace)
    assert r.returncode == 0 and not junk.exists() and (d / "servo.elf").exists()


def test_west_build_errors(workspace, tmp_path):
    r = run([west_bin(), "build", "-b", "no_such_board", "rpu_app"], cwd=workspace)
    assert r.returncode != 0 and "unknown board" in (r.stdout + r.stderr)
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "precious.txt").write_text("keep me")
    r = run([west_bin(), "build", "-p", "always", "-b", BOARD, "-d", str(foreign), "rpu_app"], cwd=workspace)
    assert r.returncode != 0 and (foreign / "precious.txt").exists()


def test_build_py_without_west(tmp_path, toolchain):
    d = tmp_path / "b"
    r = run([sys.executable, str(BUILD_PY), "-b", BOARD, "-d", str(d), "rpu_app"], cwd=tmp_path)
    assert r.returncode == 0, r.stdout + r.stderr
    assert (d / "servo.elf").is_file()


@pytest.mark.parametrize("board", ["zynq7000_qemu", "zynqmp_qemu"])
def test_west_build_can_variant(workspace, board):
    """--variant can: boards/<board>/servo-can.dts (the four axes on CAN
    drives) into build/rpu_app/<board>-can, where the images' build puts it
    (python/servoamp/images.py); the R5's too (issue 35, item 4)."""
    r = run([west_bin(), "build", "-b", board, "--variant", "can", "rpu_app"], cwd=workspace)
    assert r.returncode == 0, r.stdout + r.stderr
    out = workspace / "build" / "rpu_app" / f"{board}-can"
    assert (out / "servo.elf").is_file()
    hdr = (out / "board_config.h").read_text()
    assert "#define BOARD_CAN_AXES BOARD_U(4)" in hdr and f'"{board}"' in hdr
    assert json.loads((out / ".servoamp-build.json").read_text()) == {
        "board": board, "source": str(workspace / "rpu_app"), "variant": "can"}
    r = run([west_bin(), "build", "-b", board, "--variant", "nope", "rpu_app"], cwd=workspace)
    assert r.returncode != 0 and "no variant 'nope'" in (r.stdout + r.stderr)
