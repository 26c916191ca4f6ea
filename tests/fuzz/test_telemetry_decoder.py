"""The short run of the telemetry decoder fuzzer (tests/fuzz/fuzz_telemetry.py).

Derandomized (the same examples every run, so it is not flaky), a bounded
number of examples per target; the long run is
`.venv/bin/python tests/fuzz/fuzz_telemetry.py --seconds N`.
"""

from __future__ import annotations

import math
import struct
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

import fuzz_telemetry as ft
from servoamp import telemetry as tw

SHORT = {"decoder": 1500, "stream": 500, "recorder": 300}


def _short_run(target: str) -> None:
    counter = [0]
    test = ft.make_test(target, counter)
    test = settings(max_examples=SHORT[target], derandomize=True, deadline=None,
                    database=None, suppress_health_check=list(HealthCheck))(test)
    test()
    assert counter[0] >= SHORT[target] // 2  # it did run (Hypothesis may stop early)


@pytest.mark.parametrize("target", list(SHORT))
def test_fuzz_short(target: str) -> None:
    _short_run(target)


# Inputs the issue and the fuzzer named, kept as plain cases.
_P = tw.encode_param(1, 2, 3, 1.0, "pos_kp")
KNOWN = [
    (tw.MSG_PARAM, _P[8:20]),  # short PARAM: struct.error before
    (tw.MSG_GAP, b"\0" * 39),
    (tw.MSG_STATS, b"\0" * 50),
    (tw.MSG_LOG, b"\0" * 20),
    (tw.MSG_QUEUES, b"\0" * 8),
    (tw.MSG_HELLO, b""),
    (tw.MSG_CYCLE, b"\0" * 51),
    (tw.MSG_PARAM, _P[8:32] + struct.pack("<d", math.nan) + _P[40:]),
    (tw.MSG_LOG, tw.encode_log(1, 2, "x")[8:28] + struct.pack("<I", 481)
     + tw.encode_log(1, 2, "x")[32:]),
]


@pytest.mark.parametrize("typ,payload", KNOWN)
def test_known_bad_payloads_raise_protocol_error(typ: int, payload: bytes) -> None:
    with pytest.raises(tw.ProtocolError):
        tw.decode(typ, payload, 2)


def test_long_run_command() -> None:
    """The long-run command works and reports executions and findings."""
    p = subprocess.run([sys.executable, str(Path(ft.__file__)), "--seconds", "3",
                        "--target", "decoder"], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stdout + p.stderr
    assert "executions" in p.stdout and "0 findings" in p.stdout, p.stdout
