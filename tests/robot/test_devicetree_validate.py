"""devicetree/validate.sh on each board's Linux DTB: servoamp's bindings
pass dt-doc-validate, and dt-validate (the board's kernel's bindings plus
servoamp's) reports nothing about servoamp's nodes (the reserved-memory
carveouts, the OCM mailbox, the cycle interrupt, the remoteproc node: on
the ZynqMP the upstream ``xlnx,zynqmp-r5fss`` binding of Linux 6.12)."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from board_params import BOARDS, board_images

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.board
@pytest.mark.parametrize("board_name", BOARDS)
def test_board_dtb_validates(board_name: str) -> None:
    board_images(board_name)            # build/boards/<board>/linux.dtb and the board's kernel source
    res = subprocess.run([str(REPO / "devicetree" / "validate.sh"), board_name], cwd=REPO,
                         capture_output=True, text=True, timeout=1200)
    assert res.returncode == 0, f"validate.sh {board_name}:\n{res.stdout[-4000:]}\n{res.stderr[-2000:]}"
    assert "servoamp nodes (reserved-memory carveout, ocm-mailbox, cycle-interrupt, remoteproc): no findings" \
        in res.stdout, res.stdout
