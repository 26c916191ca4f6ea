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
from servoamp import qemu

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
    # the servo's clock in board.yaml (servod's --servo-clock-hz, the
    # bridge's clock for the CAN frames) is the time base's
    assert qemu.Board.load(BOARD).servo["clock_hz"] == cfg["BOARD_TIMEBASE_TICKS_PER_US"] * 1_000_000


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


# ---- axes and their backends (issue 22) -----------------------------------

CAN_DTS = REPO / "boards" / BOARD / "servo-can.dts"


def axes_of(hdr: str) -> list[tuple[int, str, int, int]]:
    block = re.search(r"#define BOARD_AXES\(X\) \\\n(.*?)\n\n", hdr, re.S)
    assert block, hdr
    return [(int(i), be, int(b), int(n))
            for i, be, b, n in re.findall(r"X\((\d+), (AXIS_BACKEND_\w+), (\d+), (\d+)\)", block.group(1))]


def test_default_axes_are_the_internal_model(tmp_path):
    """The board's default: today's 4 internal-model axes, no CAN bus used."""
    assert gen(DTS, tmp_path).returncode == 0
    hdr = (tmp_path / "board_config.h").read_text()
    cfg = parse_board_config(tmp_path / "board_config.h")
    assert axes_of(hdr) == [(i, "AXIS_BACKEND_MODEL", 0, 0) for i in range(4)]
    assert cfg["BOARD_CAN_AXES"] == 0 and cfg["BOARD_CAN_USED_MASK"] == 0
    assert cfg["BOARD_CAN_COUNT"] == 2
    assert (cfg["BOARD_CAN0_BASE"], cfg["BOARD_CAN0_IRQ"]) == (0xE0008000, 60)
    assert (cfg["BOARD_CAN1_BASE"], cfg["BOARD_CAN1_IRQ"]) == (0xE0009000, 83)


def test_can_board_four_drives_two_per_bus(tmp_path):
    r = gen(CAN_DTS, tmp_path)
    assert r.returncode == 0, r.stderr
    hdr = (tmp_path / "board_config.h").read_text()
    cfg = parse_board_config(tmp_path / "board_config.h")
    assert axes_of(hdr) == [(0, "AXIS_BACKEND_CAN", 0, 1), (1, "AXIS_BACKEND_CAN", 0, 2),
                            (2, "AXIS_BACKEND_CAN", 1, 1), (3, "AXIS_BACKEND_CAN", 1, 2)]
    assert cfg["BOARD_CAN_AXES"] == 4 and cfg["BOARD_CAN_USED_MASK"] == 3
    assert cfg["BOARD_CAN_BITRATE"] == 1_000_000 and cfg["BOARD_CAN_REF_HZ"] == 100_000_000
    assert cfg["BOARD_CAN_PRIORITY"] < cfg["BOARD_CYCLE_PRIORITY"]
    assert cfg["BOARD_CAN_HEARTBEAT_CONSUMER_MS"] > cfg["BOARD_CAN_HEARTBEAT_PRODUCER_MS"]
    # SYNC + 2 x (RPDO + TPDO), worst-case stuffing, at 1 Mbit/s and 1 kHz
    # SYNC 55 + 2 x (RPDO 115 + TPDO 115 + heartbeat 65) + the master's time
    # stamp 95 (can-time-stamp-ms) worst-case bits of 1000
    assert cfg["BOARD_CAN_TIME_STAMP_MS"] == 1000
    assert cfg["BOARD_CAN0_LOAD_PERMILLE"] == cfg["BOARD_CAN1_LOAD_PERMILLE"] == 740
    for k, v in CONTRACT.items():
        assert cfg[k] == v, k
    mmu = re.findall(r"X\((0x[0-9a-f]+)u, (0x[0-9a-f]+)u, (MMU_\w+)\)", hdr)
    assert {m[0] for m in mmu if m[2] == "MMU_DEVICE"} == {"0xe0000000", "0xf8000000", "0xf8f00000"}


def _can_variant(tmp_path, axis_body: str, extra: str = ""):
    src = tmp_path / "servo.dts"
    src.write_text(DTS.read_text())
    (tmp_path / "bad.dts").write_text(f'/include/ "servo.dts"\n{extra}\n{axis_body}\n')
    return gen(tmp_path / "bad.dts", tmp_path / "out")


@pytest.mark.parametrize("body,msg", [
    ('&axis0 { servoamp,backend = "can"; servoamp,can-bus = <0>; servoamp,node-id = <0>; };', "node-id"),
    ('&axis0 { servoamp,backend = "can"; servoamp,can-bus = <0>; servoamp,node-id = <128>; };', "node-id"),
    ('&axis0 { servoamp,backend = "can"; servoamp,can-bus = <2>; servoamp,node-id = <1>; };', "can-bus"),
    ('&axis0 { servoamp,backend = "can"; servoamp,can-bus = <0>; };', "servoamp,node-id"),
    ('&axis0 { servoamp,backend = "ethercat"; };', "backend"),
    ('&axis0 { servoamp,backend = "can"; servoamp,can-bus = <0>; servoamp,node-id = <3>; };\n'
     '&axis1 { servoamp,backend = "can"; servoamp,can-bus = <0>; servoamp,node-id = <3>; };', "already used"),
    ('&axis3 { reg = <5>; };', "without gaps"),
    ('&servo { can-priority = <0xa8>; };', "can-priority"),
    ('&servo { can-heartbeat-consumer-ms = <10>; };', "can-heartbeat-consumer-ms"),
    ('&axis0 { servoamp,backend = "can"; servoamp,can-bus = <0>; servoamp,node-id = <127>; };',
     "the master's own"),
    ('&servo { can-time-stamp-ms = <70000>; };', "can-time-stamp-ms"),
])
def test_generator_rejects_bad_axes(tmp_path, body, msg):
    r = _can_variant(tmp_path, body)
    assert r.returncode != 0, "accepted:\n" + body
    assert msg in r.stderr, r.stderr


def test_node_127_with_the_time_stamp_off(tmp_path):
    """Node id 127 is the master's (its time stamp PDO 0x1FF) only while
    the master sends time stamps; off, a drive may take it, and the
    worst-case bus load leaves the stamp out."""
    r = _can_variant(tmp_path, '&axis0 { servoamp,backend = "can"; servoamp,can-bus = <0>; '
                               'servoamp,node-id = <127>; };', '&servo { can-time-stamp-ms = <0>; };')
    assert r.returncode == 0, r.stderr
    cfg = parse_board_config(tmp_path / "out" / "board_config.h")
    assert cfg["BOARD_CAN_TIME_STAMP_MS"] == 0
    assert cfg["BOARD_CAN0_LOAD_PERMILLE"] == (55 + 115 + 115 + 65) * 1000 // 1000


def test_generator_rejects_a_bus_over_budget(tmp_path):
    """At a 500 us cycle, two drives on one bus need more bit times than 1 Mbit/s gives; one fits."""
    body = "\n".join(f'&axis{i} {{ servoamp,backend = "can"; servoamp,can-bus = <0>; '
                     f'servoamp,node-id = <{i + 1}>; }};' for i in range(2))
    r = _can_variant(tmp_path, body, '&servo { cycle-period-us = <500>; };')
    assert r.returncode != 0
    assert "bit times per cycle" in r.stderr
    r = _can_variant(tmp_path, body.split("\n")[0], '&servo { cycle-period-us = <500>; };')
    assert r.returncode == 0, r.stderr
