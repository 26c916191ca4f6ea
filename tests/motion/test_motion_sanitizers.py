"""The C unit tests again under AddressSanitizer + UBSan, and the threaded
ones under ThreadSanitizer.  Streaming runs are shortened (the full
1,000,000-line run is in the host build)."""
from __future__ import annotations

import pytest

from motion_helpers import TEST_BINARIES, require, run_binary

SHORT = {"MOTION_STREAM_LINES": "100000", "MOTION_STREAM_THREADED_LINES": "20000", "MOTION_RING_ITEMS": "500000",
         "MOTION_LANES_BLOCKS": "100"}
SAN_ENV = {
    "ASAN_OPTIONS": "detect_leaks=1:abort_on_error=0:halt_on_error=1",
    "UBSAN_OPTIONS": "print_stacktrace=1:halt_on_error=1",
    "TSAN_OPTIONS": "halt_on_error=1:second_deadlock_stack=1",
}


@pytest.mark.parametrize("binary", TEST_BINARIES)
def test_asan_ubsan(binary: str) -> None:
    b = require("asan")
    proc = run_binary(b, binary, [], env={**SHORT, **SAN_ENV})
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out[-6000:]
    assert "ERROR: AddressSanitizer" not in out
    assert "runtime error" not in out
    assert " passed" in proc.stdout


@pytest.mark.parametrize(
    "binary,cases",
    [
        ("test_ring", ["spsc_threads"]),
        ("test_sched_threads", []),
        ("test_threads", []),
        ("test_end_wait", []),
        ("test_lanes", ["pool_matches_sync"]),
        ("test_stream", ["stream_threaded"]),
    ],
)
def test_tsan(binary: str, cases: list[str]) -> None:
    b = require("tsan")
    env = {**SAN_ENV, "MOTION_STREAM_THREADED_LINES": "20000", "MOTION_RING_ITEMS": "200000",
           "MOTION_LANES_BLOCKS": "100"}
    proc = run_binary(b, binary, cases, env=env)
    out = proc.stdout + proc.stderr
    assert "WARNING: ThreadSanitizer" not in out, out[-6000:]
    assert proc.returncode == 0, out[-6000:]
