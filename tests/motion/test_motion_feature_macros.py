"""The library and its scheduler tests built with _GNU_SOURCE on the command
line, as a program that wants CPU affinity or SCHED_FIFO (servod) would build
them.  glibc then defines more names (e.g. SCHED_IDLE, a Linux scheduling
policy, as a macro), and the scheduler's choice kinds used one of those
names: a file that included <pthread.h> first did not compile, and the
scheduler (motion/src/scheduler.c), which included it after, dispatched
"idle" as 5, so the synchronous pipeline spun forever."""
from __future__ import annotations

import subprocess
from pathlib import Path

from motion_helpers import BUILD, ROOT

SRC = ROOT / "motion" / "src"
TESTS = ROOT / "motion" / "tests"


def build(out: Path, test: str) -> None:
    cmd = ["gcc", "-std=c11", "-D_GNU_SOURCE", "-Wall", "-Wextra", "-Werror", "-O1",
           f"-I{ROOT / 'motion' / 'include'}", f"-I{SRC}", f"-I{TESTS}", f"-I{ROOT / 'include'}",
           *[str(p) for p in sorted(SRC.glob("*.c")) if p.name != "cli.c"],
           str(TESTS / "check.c"), str(TESTS / test), "-lpthread", "-lm", "-o", str(out)]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]


def test_gnu_source_build_runs_the_scheduler_and_pipeline() -> None:
    out_dir = BUILD / "gnu"
    out_dir.mkdir(parents=True, exist_ok=True)
    for test in ("test_sched.c", "test_threads.c"):
        exe = out_dir / test.removesuffix(".c")
        build(exe, test)
        proc = subprocess.run([str(exe)], capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
