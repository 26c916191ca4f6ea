# SPDX-License-Identifier: MIT
"""Every build entry point works alone, from an empty build/, in a fresh
copy of the tree.

Each case copies the repository's files (tracked and new, as git lists
them; no build/) into an empty folder and runs ONE entry point there, the
way a new user's first command would, then checks that each component's
output is where its own Makefile says. Nothing else has built before it in
that tree, so a step that only works because another one ran first fails
here. The first case is the failure a new user hit: servod built with
BUILD= on the command line sent motion's libmotion.a to the wrong folder,
because command-line variables reach every sub-make through MAKEFLAGS.

The kernel and the initramfs come from their caches (keyed by their inputs,
built on first use); everything under build/ is new in each copy. The
Python environment is the one scripts/bootstrap.sh made (linked, not
copied).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
BOARD = "zynq7000_qemu"


def _copy_tree(dest: Path) -> Path:
    files = subprocess.run(
        ["git", "-C", str(REPO), "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
        check=True, capture_output=True,
    ).stdout.split(b"\0")
    for f in filter(None, files):
        rel = Path(os.fsdecode(f))
        src = REPO / rel
        if not src.is_file():          # deleted in the work tree, not yet committed
            continue
        (dest / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(src, dest / rel)
    if (REPO / ".venv").exists():
        (dest / ".venv").symlink_to(REPO / ".venv")
    assert not (dest / "build").exists()
    return dest


def _run(tree: Path, *cmd: str | Path, timeout: float = 600) -> str:
    env = {k: v for k, v in os.environ.items() if k not in ("MAKEFLAGS", "MAKELEVEL", "MFLAGS")}
    res = subprocess.run([str(c) for c in cmd], cwd=tree, env=env, text=True,
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT, timeout=timeout)
    assert res.returncode == 0, f"{' '.join(map(str, cmd))} failed ({res.returncode}):\n{res.stdout[-4000:]}"
    return res.stdout


def _need(*tools: str) -> None:
    missing = [t for t in tools if not shutil.which(t)]
    if missing:
        pytest.skip(f"{', '.join(missing)} missing: run scripts/bootstrap.sh")


@pytest.fixture
def tree(tmp_path: Path) -> Path:
    return _copy_tree(tmp_path / "servoamp")


def test_servod_with_its_own_build_dir_builds_motion_where_motion_says(tree: Path) -> None:
    _need("arm-linux-gnueabihf-gcc")
    out = tree / "build" / "elsewhere" / "servod"
    _run(tree, "make", "-s", "-C", "linux/servod", f"BUILD={out}", "-j2")
    assert (out / "servod").is_file() and (out / "ampctl").is_file()
    # motion's output lives where motion/Makefile puts it, not under servod's BUILD
    assert (tree / "build" / "motion" / "armhf" / "libmotion.a").is_file()
    assert not (out / "armhf").exists()


def test_motion_alone(tree: Path) -> None:
    _run(tree, "make", "-s", "-C", "motion", "-j2", "host")
    for name in ("libmotion.a", "motion_cli", "motion_bench", "test_motion"):
        assert (tree / "build" / "motion" / "host" / name).is_file(), name


def test_amp_lib_benchmarks_alone(tree: Path) -> None:
    _need("arm-none-eabi-gcc")
    _run(tree, "make", "-s", "-C", "amp_lib", "-j2", "bench")
    assert (tree / "build" / "amp_lib" / "none" / "transport_bench").is_file()
    out = _run(tree, sys.executable, "bench/amp_footprint.py", "--json", tree / "build" / "footprint.json")
    assert (tree / "build" / "footprint.json").is_file(), out


def test_west_build_alone(tree: Path) -> None:
    _need("arm-none-eabi-gcc")
    d = tree / "build" / "my-firmware"
    _run(tree, sys.executable, "scripts/west_commands/build.py", "-b", BOARD, "-d", d, "rpu_app")
    assert (d / "servo.elf").is_file() and (d / "servo-norsc.elf").is_file()


@pytest.mark.board
def test_emu_images_alone(tree: Path) -> None:
    """What the demo, ``west emu`` and every board test build first: all the
    images of a boot (kernel and initramfs from their caches)."""
    _need("arm-linux-gnueabihf-gcc", "arm-none-eabi-gcc")
    _run(tree, sys.executable, "scripts/west_commands/emu.py", "--build-only", timeout=1800)
    build = tree / "build"
    # the board's kernel: build/kernel-rt, or build/kernel for SERVOAMP_KERNEL=vanilla
    kernel = os.environ.get("SERVOAMP_KERNEL") or "rt"
    assert (build / ("kernel" if kernel == "vanilla" else f"kernel-{kernel}") / "zImage").is_file()
    assert (build / "linux" / "servod" / "servod").is_file()
    assert (build / "motion" / "armhf" / "libmotion.a").is_file()
    assert (build / "firmware" / BOARD / "rpu_app.elf").is_file()
    assert (build / "boards" / BOARD / "linux.dtb").is_file()
    assert list((build / "linux" / "remoteproc").glob("*/zynq_servo_rproc.ko"))
    assert list((build / "linux" / "uio").glob("*/servoamp_cycle_uio.ko"))
