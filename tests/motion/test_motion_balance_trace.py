"""The hybrid scheduler's balance experiment (docs/origins.md), checked from the exported queue-level CSV: 150
items placed upstream of 6 chained tasks; under the hybrid rules the
queues settle into a balanced staircase (equal upstream-minus-downstream
differences), as in the paper's figure 13."""
from __future__ import annotations

import csv
from pathlib import Path

from motion_helpers import require, run_binary


def test_queues_converge_to_balance(tmp_path: Path) -> None:
    b = require("host")
    out = tmp_path / "balance.csv"
    proc = run_binary(b, "test_sched", ["hybrid_balance"], env={"SCHED_TRACE_CSV": str(out)})
    assert proc.returncode == 0, proc.stdout
    with out.open() as f:
        rows = [[int(v) for v in r.values()] for r in csv.DictReader(f)]
    levels = [r[1:] for r in rows]  # q0..q5
    # the first sample is taken after the first step: 149 + 1
    assert sum(levels[0]) == 150 and levels[0][0] == 149 and sum(levels[-1]) == 0
    # after the first item was delivered (150 - sum of the levels), while
    # q0 still holds items, the differences q[i] - q[i+1] (the last task drains to the
    # sender) stay within 3 of each other
    started = False
    spreads = []
    for lv in levels:
        if sum(lv) < 150:
            started = True
        if not started or lv[0] == 0:
            continue
        diffs = [lv[i] - lv[i + 1] for i in range(5)] + [lv[5]]
        spreads.append(max(diffs) - min(diffs))
    assert len(spreads) > 100
    assert max(spreads) <= 3, max(spreads)
    # and the intermediate queues do fill: the staircase is not all zeros
    assert max(lv[3] for lv in levels) >= 10
