"""The benchmark runs in a tiny configuration and writes valid JSON (no
timing assertions: the figures live in bench/results/motion.json)."""
from __future__ import annotations

import json
from pathlib import Path

from motion_helpers import require, run_binary


def test_bench_tiny_writes_json(tmp_path: Path) -> None:
    b = require("host")
    out = tmp_path / "motion.json"
    proc = run_binary(b, "motion_bench",
                      ["--blocks", "300", "--arcs", "200", "--reps", "1", "--chord", "1",
                       "--json", str(out)])
    assert proc.returncode == 0, proc.stdout + proc.stderr
    data = json.loads(out.read_text())
    for key in ("single_thread", "single_thread_scurve"):
        single = data[key]
        assert single["blocks"] > 0 and single["blocks_per_s"] > 0
    assert data["single_thread"]["profile"] == "trapezoidal"
    assert data["single_thread_scurve"]["segments"] == data["single_thread"]["segments"]
    for key, profile in (("scheduler", "trapezoidal"),
                         ("scheduler_scurve", "jerk-limited (S-curve)")):
        sched = data[key]
        assert sched["program"] == "short arcs, chord tolerance 1 um"
        assert sched["profile"] == profile
        for cfg in ("hybrid_1", "hybrid_n", "fifo_1", "fifo_n", "hybrid_n_rule2"):
            assert sched[cfg]["wall_s"] > 0
        assert sched["speedup_hybrid_n_over_1"] > 0
        assert sched["speedup_hybrid_rule2_as_written_n_over_1"] > 0
        assert abs(sum(sched["task_time_share"].values()) - 1.0) < 1e-3
    # S-curve profiles take more cycles for the same path
    assert data["scheduler_scurve"]["setpoints"] > data["scheduler"]["setpoints"]
    assert "blocks/s" in proc.stdout


def test_bench_only_one_profile_and_bad_option(tmp_path: Path) -> None:
    b = require("host")
    out = tmp_path / "motion.json"
    proc = run_binary(b, "motion_bench",
                      ["--blocks", "100", "--arcs", "100", "--reps", "1", "--chord", "1",
                       "--only", "scurve", "--json", str(out)])
    assert proc.returncode == 0, proc.stdout + proc.stderr
    data = json.loads(out.read_text())
    assert "scheduler_scurve" in data and "scheduler" not in data
    bad = run_binary(b, "motion_bench", ["--only", "parabolic"])
    assert bad.returncode == 2
    assert "bad option value" in bad.stderr
