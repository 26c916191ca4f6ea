"""Build and run helpers for the motion pipeline tests (C code in motion/)."""
from __future__ import annotations

import fcntl
import os
import subprocess
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
BUILD = ROOT / "build" / "motion"
TEST_BINARIES = (
    "test_end_wait",
    "test_gcode",
    "test_lanes",
    "test_motion",
    "test_plan",
    "test_ring",
    "test_sched",
    "test_sched_threads",
    "test_stream",
    "test_threads",
)


@dataclass(frozen=True)
class Build:
    variant: str
    ok: bool
    log: str

    @property
    def dir(self) -> Path:
        return BUILD / self.variant

    def binary(self, name: str) -> Path:
        return self.dir / name


@lru_cache(maxsize=None)
def build(variant: str) -> Build:
    """Builds one variant (host, asan, tsan) once per session; serialised
    with a lock file so that parallel pytest runs do not race in make."""
    BUILD.mkdir(parents=True, exist_ok=True)
    with open(BUILD / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        proc = subprocess.run(
            ["make", "-C", str(ROOT / "motion"), "-j2", variant],
            capture_output=True,
            text=True,
            timeout=600,
        )
    return Build(variant, proc.returncode == 0, proc.stdout + proc.stderr)


def require(variant: str) -> Build:
    b = build(variant)
    if not b.ok:
        pytest.fail(f"make {variant} failed:\n{b.log[-4000:]}")
    return b


def list_cases(variant: str, binary: str) -> list[str]:
    b = build(variant)
    if not b.ok:
        return ["<build failed>"]
    out = subprocess.run(
        [str(b.binary(binary)), "--list"], capture_output=True, text=True, timeout=60
    )
    return [line for line in out.stdout.split() if line]


def run_binary(
    b: Build, binary: str, args: list[str], env: dict[str, str] | None = None,
    timeout: float = 300,
) -> subprocess.CompletedProcess[str]:
    full_env = dict(os.environ)
    full_env.update(env or {})
    return subprocess.run(
        [str(b.binary(binary)), *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=full_env,
    )

