# SPDX-License-Identifier: MIT
"""Our QEMU's GIC banks the pending state of a PPI per CPU on a clear
(emulator/qemu/patches/0005), as the GIC architecture says.

Upstream QEMU 10.0.2 cleared a PPI's pending state on every CPU when one
CPU wrote GICD_ICPENDR0. On the emulated board that stopped Linux's tick
for good (issue 20, the demo's hang in crash recovery): the servo firmware
on CPU1, starting, clears the pending state of its private-timer interrupt
(PPI 29); when CPU0's own private timer, Linux's one-shot tick, had fired
and was still pending, it was lost, and no new edge ever came.

A bare-metal program on both CPUs (fixtures/gic_ppi_pending.S) shows it
without Linux: CPU0 sets its PPI 29 pending, CPU1 sets and clears its own,
CPU0 reads its own again. Red on the unpatched build (the bit is gone),
green on ours. ``SERVOAMP_QEMU=/path/to/qemu-system-aarch64`` runs it against
another build.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import time
from pathlib import Path

import pytest

from servoamp import qemu

HERE = Path(__file__).resolve().parent
RESULT = 0x00200000
LOAD = 0x00100000
PPI_BIT = 1 << 29

pytestmark = pytest.mark.board


def _build(tmp: Path) -> Path:
    if not shutil.which("arm-none-eabi-gcc"):
        pytest.skip("arm-none-eabi-gcc missing: run scripts/bootstrap.sh")
    elf = tmp / "gic_ppi_pending.elf"
    subprocess.run(["arm-none-eabi-gcc", "-mcpu=cortex-a9", "-nostdlib", "-nostartfiles",
                    f"-Wl,-Ttext={LOAD:#x}", "-o", str(elf), str(HERE / "fixtures" / "gic_ppi_pending.S")],
                   check=True)
    return elf


def _words(m: qemu.QemuMachine, n: int) -> list[int]:
    out = m.hmp(f"xp /{n}wx {RESULT:#x}")
    return [int(w, 16) for w in re.findall(r"0x([0-9a-fA-F]{8})\b", out.split(":", 1)[1])][:n]


def test_ppi_pending_clear_is_banked_per_cpu(tmp_path: Path) -> None:
    elf = _build(tmp_path)
    extra = ["-device", f"loader,file={elf},cpu-num=0",
             "-device", f"loader,addr={LOAD:#x},cpu-num=1"]
    m = qemu.QemuMachine(qemu.Board.load("zynq7000_qemu"), None, run_dir=tmp_path / "qemu", extra_args=extra)
    with m.start():
        deadline = time.monotonic() + 30
        while (w := _words(m, 5))[0] != 3:
            assert time.monotonic() < deadline, f"the program did not finish: {[hex(x) for x in w]}"
            time.sleep(0.05)
    flag, cpu0_set, cpu1_after_clear, cpu0_after_cpu1, cpu0_after_own = w
    assert cpu0_set & PPI_BIT, "CPU0's GICD_ISPENDR0 write did not make PPI 29 pending"
    assert not cpu1_after_clear & PPI_BIT, "CPU1's GICD_ICPENDR0 write did not clear its own PPI 29"
    assert cpu0_after_cpu1 & PPI_BIT, (
        "CPU1's GICD_ICPENDR0 write cleared CPU0's pending PPI 29 (the GIC model does not bank the "
        "clear: Linux's tick on the board is lost when the firmware starts)")
    assert not cpu0_after_own & PPI_BIT, "CPU0's own GICD_ICPENDR0 write did not clear its PPI 29"
