"""Recovery that always ends (issue 20, item 1), a short run of the
recovery stress (python -m servoamp.recovery_stress) in the test suite:
hang-and-recover rounds with a CPU hog in the guest, and remoteproc
stop/start rounds, each in ONE boot, with console input typed at varied
moments of the detection, the reload and the restart.

Before our QEMU's patch 0005 (GICD_ICPENDR0 banked per CPU), the firmware
starting on CPU1 could clear CPU0's pending private-timer interrupt, and
Linux's tick stopped for good: the console went silent within 3 to 10
rounds (docs/reliability.md has the rates of the long runs before and
after). Any round whose console stops answering fails the test with both
vCPUs' state kept in the logs; a round must also end with the exchange
back and the parameter it set restored.

On both boards (parametrized by board, one boot per board and mode): on
the ZynqMP the hang's restart is servod's own (the upstream R5 driver has
no report_crash) and a stop powers R5 0 down through TF-A; the rounds and
their checks are the same."""

from __future__ import annotations

import pytest

from board_params import BOARDS, board_images
from servoamp import recovery_stress

pytestmark = pytest.mark.board

ROUNDS = 40


@pytest.mark.parametrize("board_name", BOARDS)
@pytest.mark.parametrize("mode,guest_load", [("hang", True), ("stopstart", False)])
def test_recovery_stress_rounds_all_end(board_name: str, mode: str, guest_load: bool) -> None:
    board, images = board_images(board_name)
    res = recovery_stress.run(ROUNDS, seed=20, guest_load=guest_load, with_host_load=False,
                              max_boots=1, mode=mode, console_timeout=60.0, board=board, images=images)
    print(f"[stress {board_name}] {mode}: {res.rounds} rounds, {res.passed} back, {res.slow} slow, {res.lost} lost, "
          f"{res.hangs} hangs, {res.seconds:.0f} s; kernel detectors: {res.detectors or 'none'}; "
          f"logs: {res.kept_logs}", flush=True)
    assert res.hangs == 0, f"the console stopped answering in round(s) {res.hang_rounds}: {res.kept_logs}"
    assert res.rounds == ROUNDS and res.passed == ROUNDS, res
    assert not res.detectors, res.detectors
