# SPDX-License-Identifier: MIT
"""rpu_app for the ZynqMP's Cortex-R5F (platform rpu_app/platform/zynqmp_r5,
boards/zynqmp_qemu/servo.dts), without booting: the servo devicetree
compiles and agrees with board.yaml, the generator picks the R5 platform by
the CPU and refuses what an R5 cannot have, and the ELF is what Linux's
upstream xlnx_r5_remoteproc loads and starts (the vectors at 0x0 in the
ATCM, everything else in the DDR carveout, hard float for the R5, a trace
buffer in the non-cacheable top). Booting it: tests/robot/zynqmp/04_rpu_app."""
from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from elftools.elf.elffile import ELFFile

from rpu_common import REPO, parse_board_config
from servoamp import qemu

BOARD = "zynqmp_qemu"
pytestmark = pytest.mark.on_board(BOARD)
DTS = REPO / "boards" / BOARD / "servo.dts"
GEN = REPO / "rpu_app" / "scripts" / "gen_board_header.py"


def gen(dts: Path, out: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, str(GEN), "--dts", str(dts), "--board", BOARD,
                           "--out-dir", str(out)], capture_output=True, text=True)


@pytest.fixture(scope="module")
def build(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("r5")
    r = subprocess.run(["make", "-C", str(REPO / "rpu_app"), "-j2", f"BOARD={BOARD}", f"BUILD={out}",
                        f"PYTHON={sys.executable}"], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    return out


def test_dtc_compiles_without_warnings(tmp_path: Path) -> None:
    dtc = shutil.which("dtc")
    if not dtc:
        pytest.skip("dtc missing: run scripts/bootstrap.sh")
    r = subprocess.run([dtc, "-I", "dts", "-O", "dtb", "-o", str(tmp_path / "servo.dtb"), str(DTS)],
                       capture_output=True, text=True)
    assert r.returncode == 0 and r.stderr.strip() == "", r.stderr


def test_generator_picks_the_r5_platform_and_agrees_with_board_yaml(tmp_path: Path) -> None:
    r = gen(DTS, tmp_path)
    assert r.returncode == 0, r.stderr
    assert "PLATFORM := zynqmp_r5" in (tmp_path / "board_config.mk").read_text()
    cfg = parse_board_config(tmp_path / "board_config.h")
    board = qemu.Board.load(BOARD)
    car = board.data["servo"]["carveouts"]["r5_0"]
    assert (cfg["BOARD_CARVEOUT_BASE"], cfg["BOARD_CARVEOUT_SIZE"]) == (car["fw_image"], car["fw_size"])
    assert (cfg["BOARD_AMP_BASE"], cfg["BOARD_AMP_SIZE"]) == (
        board.addr("servo", "mailbox", "base"), board.addr("servo", "mailbox", "size"))
    assert (cfg["BOARD_GICD_BASE"], cfg["BOARD_GICC_BASE"]) == (
        board.addr("rpu_gic", "dist"), board.addr("rpu_gic", "cpu"))
    assert cfg["BOARD_UART_BASE"] == [u["base"] for u in board.qemu["uarts"] if u["owner"] == "servo"][0]
    assert (cfg["BOARD_CPU_HAS_VBAR"], cfg["BOARD_GIC_OWNED"], cfg["BOARD_HAS_STOP_CONTRACT"]) == (0, 1, 0)
    assert cfg["BOARD_VECTORS_BASE"] == 0
    # the cycle: the PL's timer, counter 0 on IRQ0[0] (SPI 89), counter 1
    # (Linux's) on IRQ0[1]; mapped as a device, execute-never
    pl = board.data["pl_timer"]
    assert cfg["BOARD_TTC_BASE"] == pl["base"]
    assert (cfg["BOARD_CYCLE_COUNTER"], cfg["BOARD_LINUX_CYCLE_COUNTER"]) == (0, 1)
    assert (cfg["BOARD_CYCLE_IRQ"], cfg["BOARD_LINUX_CYCLE_IRQ"]) == (32 + pl["spi"], 32 + pl["spi"] + 1)
    header = (tmp_path / "board_config.h").read_text()
    regions = re.findall(r"X\((0x[0-9a-f]+)u, (0x[0-9a-f]+)u, (MPU_\w+)\)", header)
    assert 1 + len(regions) <= 16                # and the stack guard
    for base, size, _ in regions:
        b, s = int(base, 16), int(size, 16)
        assert s & (s - 1) == 0 and b % s == 0, (base, size)
    assert ("0x80000000", "0x00001000", "MPU_DEVICE") in [
        (b, f"0x{int(s, 16):08x}", a) for b, s, a in regions], regions


@pytest.mark.parametrize("edit,why", [
    (("reg = <0x3ed00000 0x40000>;", "reg = <0x3ed00000 0x30000>;"), "power of two"),
    (("reg = <0x00000000 0x10000>;", "reg = <0x00010000 0x10000>;"), "vectors must be at 0x0"),
    (("stats-cycles = <1000>;", "stats-cycles = <1000>;\n\t\tidle-wake-us = <10000>;"), "has none"),
    (("compatible = \"arm,cortex-r5f\";", "compatible = \"arm,cortex-m4\";"), "no platform"),
    (("interrupts = <0 89 4>, <0 90 4>", "interrupts = <0 170 4>, <0 90 4>"), "beyond the 192 interrupt IDs"),
])
def test_generator_refuses_what_an_r5_cannot_have(tmp_path: Path, edit: tuple[str, str], why: str) -> None:
    text = DTS.read_text()
    assert edit[0] in text
    bad = tmp_path / "servo.dts"
    bad.write_text(text.replace(edit[0], edit[1], 1))
    r = gen(bad, tmp_path / "out")
    assert r.returncode != 0 and why in r.stderr, r.stderr


def test_elf_is_what_the_upstream_driver_loads(build: Path) -> None:
    cfg = parse_board_config(build / "board_config.h")
    lo, hi = cfg["BOARD_CARVEOUT_BASE"], cfg["BOARD_CARVEOUT_BASE"] + cfg["BOARD_CARVEOUT_SIZE"]
    for name in ("servo.elf", "servo-norsc.elf"):
        with (build / name).open("rb") as f:
            elf = ELFFile(f)
            assert elf["e_machine"] == "EM_ARM"
            assert elf["e_flags"] & 0x400, "hard-float ABI (EF_ARM_ABI_FLOAT_HARD)"
            assert lo <= elf["e_entry"] < hi, "entry in the carveout (below 0xfffc0000: low vectors)"
            vec = elf.get_section_by_name(".vectors")
            assert vec is not None and vec["sh_addr"] == 0
            for seg in elf.iter_segments():
                if seg["p_type"] != "PT_LOAD":
                    continue
                a, n = seg["p_paddr"], seg["p_memsz"]
                in_atcm = a + n <= cfg["BOARD_VECTORS_SIZE"]
                in_carveout = lo <= a and a + n <= hi
                assert in_atcm or in_carveout, f"{name}: segment {a:#x}+{n:#x} outside ATCM and carveout"
            has_rsc = elf.get_section_by_name(".resource_table") is not None
            assert has_rsc == (name == "servo.elf")
    attrs = subprocess.run(["arm-none-eabi-readelf", "-A", str(build / "servo.elf")], capture_output=True,
                           text=True).stdout
    assert "Tag_CPU_arch_profile: Realtime" in attrs, attrs   # ARMv7-R
    assert "VFPv3-D16" in attrs, attrs


def test_can_variant_uses_the_lpd_can_controllers(tmp_path: Path) -> None:
    """servo-can.dts (issue 35, item 4): the four axes on CiA 402 drives,
    two per bus, on the ZynqMP's CAN0/CAN1 where QEMU's xlnx-zcu102 puts
    them (hw/arm/xlnx-zynqmp.c: 0xff060000/0xff070000, SPI 23/24), at QEMU's
    24 MHz CAN_REF_CLK (1 Mbit/s reachable), both mapped by the MPU as
    device memory and nothing else added."""
    r = gen(DTS.with_name("servo-can.dts"), tmp_path)
    assert r.returncode == 0, r.stderr
    cfg = parse_board_config(tmp_path / "board_config.h")
    assert (cfg["BOARD_CAN0_BASE"], cfg["BOARD_CAN0_IRQ"]) == (0xFF060000, 32 + 23)
    assert (cfg["BOARD_CAN1_BASE"], cfg["BOARD_CAN1_IRQ"]) == (0xFF070000, 32 + 24)
    assert (cfg["BOARD_CAN_REF_HZ"], cfg["BOARD_CAN_BITRATE"]) == (24_000_000, 1_000_000)
    assert (cfg["BOARD_CAN_AXES"], cfg["BOARD_CAN_USED_MASK"]) == (4, 3)
    header = (tmp_path / "board_config.h").read_text()
    assert "X(0, AXIS_BACKEND_CAN, 0, 1)" in header and "X(3, AXIS_BACKEND_CAN, 1, 2)" in header
    mpu = re.findall(r"X\((0x[0-9a-f]+)u, (0x[0-9a-f]+)u, (MPU_\w+)\)", header)
    assert ("0xff060000", "0x00001000", "MPU_DEVICE") in mpu and ("0xff070000", "0x00001000", "MPU_DEVICE") in mpu
    assert 1 + len(mpu) <= 16
    # the model axes' build (servo.dts) maps no CAN controller
    r = gen(DTS, tmp_path / "model")
    assert r.returncode == 0, r.stderr
    assert "ff060000u" not in (tmp_path / "model" / "board_config.h").read_text().split("BOARD_MPU_REGIONS")[-1]
    # the servo's clock in board.yaml (servod's --servo-clock-hz) is the time base's
    assert qemu.Board.load(BOARD).servo["clock_hz"] == cfg["BOARD_TIMEBASE_TICKS_PER_US"] * 1_000_000
