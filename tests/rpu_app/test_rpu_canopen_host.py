# SPDX-License-Identifier: MIT
"""The servo firmware's CANopen master (rpu_app/src/canopen_master.c,
canopen_config.c, canopen_drive.c) on the host, under AddressSanitizer +
UBSan, against scripted CiA 402 drives (co_testbus.c):

- test_canopen_master.c: NMT and boot-up, the SDO configuration (CSP,
  mapping checks, heartbeat), the enable sequence, SYNC and PDOs every
  cycle, EMCY and heartbeat faults, bus-off, TX full, and malformed frames
  (DLC, node id, SDO size) plus a fuzz run;
- test_canopen_faults.c (issue 33): a heartbeat saying pre-operational or
  stopped, another master's NMT command, TPDO silence, a lost NMT start,
  unsupported PDO COB-IDs (bit 29, bit 31, bits 11-28, another id), fault
  resets that take 1 to 50 cycles, one behind a full TX FIFO, and one the
  drive refuses;

and the CANPS driver (canps.c) against a simulated controller."""
from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
TOP = HERE.parents[1]
SRC = TOP / "rpu_app" / "src"
MASTER = [SRC / "canopen_master.c", SRC / "canopen_config.c", SRC / "canopen_drive.c", HERE / "co_testbus.c"]


def _build_and_run(tmp_path: Path, test: str, sources: list[Path], *defines: str) -> str:
    if not shutil.which("cc"):
        pytest.skip("no host C compiler")
    exe = tmp_path / Path(test).stem
    cmd = ["cc", "-std=c11", "-O1", "-g", "-Wall", "-Wextra", "-Werror", "-Wpedantic", "-Wshadow",
           "-Wstrict-prototypes", "-fsanitize=address,undefined", "-fno-sanitize-recover=all",
           "-fno-omit-frame-pointer", *defines, f"-I{SRC}", f"-I{HERE}", str(HERE / test), *map(str, sources),
           "-o", str(exe)]
    subprocess.run(cmd, check=True)
    proc = subprocess.run([str(exe)], capture_output=True, text=True, timeout=120)
    out = proc.stdout + proc.stderr
    print(out)
    assert proc.returncode == 0, out
    assert " 0 failed" in out and "runtime error" not in out, out
    return out


def test_canopen_master_host(tmp_path: Path) -> None:
    out = _build_and_run(tmp_path, "test_canopen_master.c", MASTER)
    assert "both nodes in operation enabled" in out


def test_canopen_faults_host(tmp_path: Path) -> None:
    """Issue 33: each way a drive stops following faults its axis within
    its stated cycles, and one acknowledgement resets a slow drive."""
    out = _build_and_run(tmp_path, "test_canopen_faults.c", MASTER)
    assert "heartbeat 0x7f: axis faulted after 1 cycle(s), error 0xff04" in out
    assert "heartbeat 0x04: axis faulted after 1 cycle(s), error 0xff05" in out
    assert "tpdo: silent drive faulted after 3 cycles" in out
    assert "nmt start: all lost, fault 0xff07" in out
    assert "29-bit identifier (COB-ID bit 29) not supported" in out
    assert "drive needing 50 cycle(s): operation enabled 55 cycles after one resume" in out
    assert "refused by drive after 100 cycles: error 0xff09" in out


def test_canps_host(tmp_path: Path) -> None:
    """The CANPS driver against a simulated controller (register accesses
    redirected with CANPS_HOST_TEST): bit timing, filters, TX byte order and
    busy, the RX drain into the ring (bounded, overflow counted), error
    counters and passive state, bus-off restart."""
    out = _build_and_run(tmp_path, "test_canps.c", [SRC / "canps.c"], "-DCANPS_HOST_TEST")
    assert "brpr 4 btr 0x03e" in out
