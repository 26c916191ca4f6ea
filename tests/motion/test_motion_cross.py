"""armhf build with arm-linux-gnueabihf-gcc (skipped when the cross compiler
or its C library headers are missing)."""
from __future__ import annotations

import shutil
import subprocess

import pytest

from motion_helpers import BUILD, ROOT

CC = "arm-linux-gnueabihf-gcc"


def cross_usable() -> str | None:
    if shutil.which(CC) is None:
        return f"{CC} not installed"
    probe = subprocess.run([CC, "-x", "c", "-c", "-o", "/dev/null", "-"],
                           input="#include <stdint.h>\n#include <pthread.h>\nint x;\n",
                           capture_output=True, text=True)
    if probe.returncode != 0:
        return f"{CC} has no armhf C library headers (libc6-dev-armhf-cross)"
    return None


def test_cross_build_armhf() -> None:
    why = cross_usable()
    if why:
        pytest.skip(why)
    proc = subprocess.run(["make", "-C", str(ROOT / "motion"), "-j2", "cross"],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    for name in ("libmotion.a", "motion_cli", "motion_bench", "test_motion"):
        assert (BUILD / "armhf" / name).exists(), name
    head = (BUILD / "armhf" / "motion_cli").read_bytes()[:20]
    assert head[:4] == b"\x7fELF" and head[4] == 1  # 32-bit ELF
    assert int.from_bytes(head[18:20], "little") == 40  # EM_ARM
