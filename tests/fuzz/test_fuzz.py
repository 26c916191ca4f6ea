"""The libFuzzer harnesses of tests/fuzz/ (clang -fsanitize=fuzzer,address,
undefined): each is built, replays its regression inputs (one per fix the
harness found, tests/fuzz/regression/<name>/), then runs briefly from its
seed corpus (fuzzrun.py makes it from real inputs) and must find nothing.
The longer campaign is scripts/fuzz.sh."""

from __future__ import annotations

import csv
import os
import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
import fuzzrun  # noqa: E402

SHORT_RUNS = 20000
SHORT_SECONDS = 20


@pytest.fixture(scope="module")
def built() -> None:
    fuzzrun.build()


# the harnesses whose findings were fixed, each fix with its input here
WITH_REGRESSIONS = sorted(p.name for p in fuzzrun.REGRESSION.iterdir() if p.is_dir())


def test_regression_folders_are_harnesses() -> None:
    assert set(WITH_REGRESSIONS) <= set(fuzzrun.NAMES)
    assert {"amp_ocm", "rproc_check"} <= set(WITH_REGRESSIONS)


@pytest.mark.parametrize("name", WITH_REGRESSIONS)
def test_regression_inputs_pass(name: str, built: None) -> None:
    files = sorted((fuzzrun.REGRESSION / name).glob("*"))
    assert files, f"empty regression folder for {name}"
    res = fuzzrun.replay(name)
    assert res.returncode == 0, res.stderr[-4000:]
    assert res.stderr.count("Executed ") == len(files), res.stderr[-4000:]


@pytest.mark.parametrize("name", fuzzrun.NAMES)
def test_short_run_finds_nothing(name: str, built: None, tmp_path: Path) -> None:
    seeds = fuzzrun.seeds(name)
    assert any(seeds.iterdir()), f"empty seed corpus for {name}"
    res = fuzzrun.run(name, tmp_path / "corpus", seeds, tmp_path / "findings",
                      seconds=SHORT_SECONDS, runs=SHORT_RUNS)
    print(fuzzrun.table([res]))
    assert res.rc == 0 and not res.findings, res.log[-6000:]
    assert res.execs > 0 and res.coverage > 0, res.log[-3000:]


def test_driver_checks_give_the_board_suites_reasons(built: None) -> None:
    """The driver's image checks in user space (the harness, with the
    driver's messages printed) refuse each bad image of the board suite
    03_remoteproc_bad_images with the reason the suite expects from the
    kernel log (those of the core's own check aside), and accept the good
    test firmware."""
    seeds = fuzzrun.seeds("rproc_check")  # builds tests/robot/fixtures
    fixtures = fuzzrun.BUILD / "fixtures"
    with open(fixtures / "bad-images.tsv", newline="") as f:
        table = list(csv.reader(f, delimiter="\t"))
    assert len(table) >= 26
    env = dict(os.environ, SERVOAMP_FUZZ_VERBOSE="1")
    core_reasons = ("Image is corrupted", "refused by the remoteproc core", "Image is too small")
    for image, reason in table:
        res = subprocess.run([str(fuzzrun.binary("rproc_check")), str(fixtures / image)],
                             capture_output=True, text=True, env=env, timeout=60)
        assert res.returncode == 0 and "image accepted" not in res.stderr, res.stderr[-3000:]
        if not reason.startswith(core_reasons):
            assert reason in res.stderr, f"{image}: expected '{reason}' in\n{res.stderr}"
    for good in ("test-fw-rsc.elf", "test-fw-norsc.elf"):
        res = subprocess.run([str(fuzzrun.binary("rproc_check")), str(seeds / good)],
                             capture_output=True, text=True, env=env, timeout=60)
        assert res.returncode == 0, res.stderr[-3000:]
        assert "image accepted" in res.stderr and "fuzz.elf:" not in res.stderr, res.stderr[-3000:]
