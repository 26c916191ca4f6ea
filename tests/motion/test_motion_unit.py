"""Runs every case of every C test binary (host build), one pytest test per
case; a case passes when the binary exits 0 and prints `ok <case>`."""
from __future__ import annotations

import pytest

from motion_helpers import TEST_BINARIES, Build, list_cases, require, run_binary


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    if "binary_case" in metafunc.fixturenames:
        params = [
            (binary, case) for binary in TEST_BINARIES for case in list_cases("host", binary)
        ]
        metafunc.parametrize(
            "binary_case", params, ids=[f"{b}:{c}" for b, c in params]
        )


def test_case(binary_case: tuple[str, str]) -> None:
    binary, case = binary_case
    b: Build = require("host")
    proc = run_binary(b, binary, [case])
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert f"ok {case}" in proc.stdout.splitlines(), proc.stdout
