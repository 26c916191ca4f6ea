# SPDX-License-Identifier: MIT
"""boards/<board>/servo.dts and rpu_app/scripts/gen_board_header.py: the
devicetree compiles without warnings, the generator derives every number
from it, and it refuses inconsistent configurations."""
from __future__ import annotations

import re
import shutil
import subprocess
import sys

import pytest

from rpu_common import BOARD, CONTRACT, REPO, parse_board_config

DTS = REPO / "boards" / BOARD / "servo.dts"
GEN = REPO / "rpu_app" / "scripts" / "gen_board_header.py"


def gen(dts, out):
    return subprocess.run([sys.executable, str(GEN), "--dts", str(dts), "--board", BOARD,
                           "--out-dir", str(out)], capture_output=True, text=True)


def test_dtc_compiles_without_warnings(tmp_path):
    dtc = shutil.which("dtc")
    if not dtc:
        pytest.skip("dtc missing: run scripts/bootstrap.sh")
    r = subprocess.run([dtc, "-I", "dts", "-O", "dtb", "-o", str(tmp_path / "servo.dtb"), str(DTS)],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert r.stderr.strip() == "", f"dtc warnings:\n{r.stderr}"


def test_generator_output(tmp_path):
    r = gen(DTS, tmp_path)
    assert r.returncode == 0, r.stderr
    cfg = parse_board_config(tmp_path / "board_config.h")
    for k, v in CONTRACT.items():
        assert cfg[k] == v, k
    # TTC: 16-bit interval with a prescaler that reproduces the period
    div = (2 << cfg["BOARD_CYCLE_PS_V"]) if cfg["BOARD_CYCLE_PS_EN"] else 1
    ticks = cfg["BOARD_CYCLE_INTERVAL"] + 1
    assert ticks <= 0x10000
    period_ns = ticks * div * 1e9 / cfg["BOARD_TTC_HZ"]
    assert abs(period_ns - cfg["BOARD_CYCLE_PERIOD_US"] * 1000) < 100
    assert cfg["BOARD_CYCLE_IRQ_LEVEL"] == 1, "TTC interrupts are level (QEMU cadence_ttc, Zynq TRM)"
    assert cfg["BOARD_NEST_TEST_PRIORITY"] < cfg["BOARD_CYCLE_PRIORITY"]
    ld = (tmp_path / "board_memory.ld").read_text()
    assert "IMAGE (rwx) : ORIGIN = 0x1f000000, LENGTH = 0x00f00000" in ld
    assert "UNCACHED (rw) : ORIGIN = 0x1ff00000, LENGTH = 0x00100000" in ld
    hdr = (tmp_path / "board_config.h").read_text()
    mmu = re.findall(r"X\((0x[0-9a-f]+)u, (0x[0-9a-f]+)u, (MMU_\w+)\)", hdr)
    assert ("0x1f000000", "0x00f00000", "MMU_NORMAL_WB") in mmu
    assert ("0xfff00000", "0x00100000", "MMU_NORMAL_NC") in mmu
    assert {m[0] for m in mmu if m[2] == "MMU_DEVICE"} == {"0xe0000000", "0xf8000000", "0xf8f00000"}


def test_generator_is_idempotent(tmp_path):
    assert gen(DTS, tmp_path).returncode == 0
    t = (tmp_path / "board_config.h").stat().st_mtime_ns
    assert gen(DTS, tmp_path).returncode == 0
    assert (tmp_path / "board_config.h").stat().st_mtime_ns == t, "unchanged output must not be rewritten"


@pytest.mark.parametrize("old,new,msg", [
    ("cycle-period-us = <1000>;", "cycle-period-us = <2000000>;", "cycle-period-us"),
    ("cycle-counter = <0>;", "cycle-counter = <3>;", "cycle-counter"),
    ("nest-test-priority = <0x80>;", "nest-test-priority = <0xc0>;", "nest-test-priority"),
    ("uncached-size = <0x00100000>;", "uncached-size = <0x00080000>;", "uncached-size"),
    ("nest-test-sgi = <15>;", "nest-test-sgi = <3>;", "nest-test-sgi"),
])
def test_generator_rejects(tmp_path, old, new, msg):
    text = DTS.read_text()
    assert old in text
    bad = tmp_path / "servo.dts"
    bad.write_text(text.replace(old, new))
    r = gen(bad, tmp_path / "out")
    assert r.returncode != 0
    assert msg in r.stderr


def test_period_from_devicetree(tmp_path):
    """A different period in the devicetree changes the generated timer setup."""
    bad = tmp_path / "servo.dts"
    bad.write_text(DTS.read_text().replace("cycle-period-us = <1000>;", "cycle-period-us = <250>;"))
    assert gen(bad, tmp_path / "out").returncode == 0
    cfg = parse_board_config(tmp_path / "out" / "board_config.h")
    assert cfg["BOARD_CYCLE_PERIOD_US"] == 250
    div = (2 << cfg["BOARD_CYCLE_PS_V"]) if cfg["BOARD_CYCLE_PS_EN"] else 1
    assert abs((cfg["BOARD_CYCLE_INTERVAL"] + 1) * div * 1e9 / cfg["BOARD_TTC_HZ"] - 250_000) < 100
