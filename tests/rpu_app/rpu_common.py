# SPDX-License-Identifier: MIT
"""What the rpu_app tests share besides fixtures (conftest.py): the board
contract, the firmware's status words, the build, the QEMU check. A module
of its own name: several test folders have a conftest.py, and which one
"conftest" names depends on which folders pytest collected last."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
BOARD = "zynq7000_qemu"

from servoamp.qemu import rproc_words  # noqa: E402

# The board contract (fixed numbers shared with the Linux/remoteproc side).
CONTRACT = {
    "BOARD_CARVEOUT_BASE": 0x1F000000,
    "BOARD_CARVEOUT_SIZE": 0x01000000,
    "BOARD_OCM_BASE": 0xFFFC0000,
    "BOARD_OCM_SIZE": 0x00040000,
    "BOARD_PARK_ADDR": 0xFFFC0100,
    "BOARD_BOOT_REG_ADDR": 0xFFFFFFF0,
    "BOARD_AMP_BASE": 0xFFFF0000,
    "BOARD_AMP_SIZE": 0x00008000,
    "BOARD_STOP_CONTROL_ADDR": 0xFFFF8000,
    "BOARD_STOP_STATUS_ADDR": 0xFFFF8004,
    "BOARD_UART_BASE": 0xE0001000,
    "BOARD_TTC_BASE": 0xF8002000,
    "BOARD_CYCLE_IRQ": 69,
    "BOARD_GICD_BASE": 0xF8F01000,
    "BOARD_GICC_BASE": 0xF8F00100,
    "BOARD_GTIMER_BASE": 0xF8F00200,
}
# The driver's control word and the firmware's status words, from their one
# definition (include/servoamp/rproc_words.h).
_WORDS = rproc_words()
STOP, RUN, PRKD, CRSH = (_WORDS[k] for k in ("ZSR_CTRL_STOP", "ZSR_STATUS_RUNNING", "ZSR_STATUS_PARKED",
                                              "ZSR_STATUS_CRASHED"))


def parse_board_config(path: Path) -> dict[str, int]:
    cfg = {}
    for m in re.finditer(r"^#define (BOARD_\w+) BOARD_U\((0x[0-9a-fA-F]+|\d+)\)", path.read_text(), re.M):
        cfg[m.group(1)] = int(m.group(2), 0)
    return cfg


def _make(build: Path, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        ["make", "-C", str(REPO / "rpu_app"), "-j2", f"BOARD={BOARD}", f"BUILD={build}",
         f"PYTHON={sys.executable}", *extra],
        capture_output=True, text=True)


def qemu_ok() -> str | None:
    """None when the project's QEMU is there (built on first use), else why not."""
    from servoamp import qemu
    try:
        qemu.check_qemu(qemu.Board.load(BOARD))
    except qemu.QemuError as e:
        return f"no usable QEMU: {e}"
    return None
