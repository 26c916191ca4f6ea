"""bench/cycle/rt_latency_bench.py (issue 23's latency table; issue 35: the
ZynqMP's): its percentiles, the cyclictest parser, the table and the
figures on synthetic windows, the boards' kernels and the refusals of the
command line, the committed results of each board against their own
windows, and mypy --strict (the script and its two modules). No QEMU run and no figure asserted (the run
itself: bench/README.md, docs/cycle-figures.md, "Figures")."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

from servoamp import bench, qemu

TOP = Path(__file__).resolve().parents[2]
SCRIPT = TOP / "bench" / "cycle" / "rt_latency_bench.py"

CT_OUT = """\
# /dev/cpu_dma_latency set to 0us
000000 000000
000003 000990
000004 000009
000031 000001
# Total: 000001000
# Min Latencies: 00003
# Avg Latencies: 00003
# Max Latencies: 00031
# Histogram Overflows: 00000
# Histogram Overflow at cycle number:
# Thread 0:
done
"""


@pytest.fixture(scope="module")
def rb() -> ModuleType:
    spec = importlib.util.spec_from_file_location("rt_latency_bench", SCRIPT)
    assert spec and spec.loader
    mod = importlib.util.module_from_spec(spec)
    sys.modules["rt_latency_bench"] = mod
    spec.loader.exec_module(mod)
    return mod


def test_nearest_rank_percentiles(rb: ModuleType) -> None:
    v = list(range(1, 10_001))           # 1..10000
    assert rb.percentile(v, 99) == 9900 and rb.percentile(v, 99.99) == 9999
    assert rb.percentile(v, 100) == 10000 and rb.percentile(v, 0) == 1
    assert rb.percentile([7], 99.99) == 7 and rb.percentile([], 50) is None
    # 100 values: p99 is the 99th, p99.99 the largest
    w = sorted([1000] * 98 + [5000, 9000])
    assert rb.percentile(w, 99) == 5000 and rb.percentile(w, 99.99) == 9000
    s = rb.wake_summary([9000, 1000, 5000] + [1000] * 97)
    assert s == {"n": 100, "min": 1000, "p50": 1000, "p99": 5000, "p9999": 9000, "max": 9000, "mean": 1120.0}
    assert rb.wake_summary([]) == {"n": 0}


def test_histogram_percentiles_and_cyclictest_output(rb: ModuleType) -> None:
    # bucket b holds [b, b+1) us: the percentile is the bucket's upper edge
    assert rb.hist_percentile({3: 990, 4: 9, 31: 1}, 0, 99) == 4
    assert rb.hist_percentile({3: 990, 4: 9, 31: 1}, 0, 99.99) == 32
    assert rb.hist_percentile({3: 99}, 1, 99.99) is None     # in the overflows: above the histogram
    assert rb.hist_percentile({}, 0, 99) is None
    ct = rb.parse_cyclictest(CT_OUT)
    assert (ct["min"], ct["avg"], ct["max"], ct["overflows"], ct["samples"]) == (3, 3, 31, 0, 1000)
    assert ct["histogram_us"] == {"3": 990, "4": 9, "31": 1}
    assert (ct["p99"], ct["p9999"]) == (4, 32)


def _window(missed: int, wake: list[int], ct_max: int) -> dict[str, Any]:
    return {"cycles": len(wake) + missed, "missed": missed, "servod_wake_ns": {
        "n": len(wake), "min": min(wake), "p99": max(wake), "p9999": max(wake), "max": max(wake)},
        "cyclictest": {"min": 3, "avg": 3, "max": ct_max, "p99": 4, "p9999": ct_max + 1, "samples": 100}}


def _result() -> dict[str, Any]:
    return {"kernels": {
        "vanilla": {"rates": {"1000": {"windows": {"idle": _window(0, [4200, 4300], 9),
                                                   "hackbench": _window(2, [4200, 61000], 70)}}}},
        "rt": {"rates": {"4000": {"windows": {"idle": _window(0, [8800, 9000], 5)}}}},
    }}


def test_table_and_figures(rb: ModuleType) -> None:
    r = _result()
    md = rb.table_markdown(r).splitlines()
    assert md[0].startswith("| kernel | rate | load | cycles | records | missed | servod min | p99 | p99.99 | max |")
    assert len(md) == 2 + 3
    assert md[3] == "| vanilla | 1 kHz | hackbench | 4 | 2 | 2 | 4.2 | 61.0 | 61.0 | 61.0 | 3 / 3 / 70 | 4 / 71 |"
    assert md[4].startswith("| rt | 4 kHz | idle | 2 | 2 | 0 | 8.8 |")
    figs = rb.figures(r)
    names = [f["name"] for f in figs]
    assert len(names) == len(set(names))
    assert "vanilla_1khz_hackbench_wake_p9999" in names and "rt_4khz_idle_cyclictest_max" in names
    assert bench.validate({"benchmark": "rt_latency", "figures": figs}) == []
    v = rb.verdict(r)
    assert v.startswith("lower worst-case wake-up: rt") and "vanilla: 2 missed" in v


def test_merge_makes_one_table_of_separate_runs(rb: ModuleType) -> None:
    def part(kernel: str, rate: str, loads: list[str], build: str) -> dict[str, Any]:
        return {"command": f"run {kernel} {rate}", "started": "t", "cycles_per_window": 100, "qemu": {"key": "q"},
                "kernels": {kernel: {"kernel": kernel, "build": {"initramfs_sha256": build},
                                     "rates": {rate: {"period_us": 1_000_000 // int(rate),
                                                      "windows": {ld: _window(0, [8800, 9000], 5) for ld in loads}}}}}}
    a = part("vanilla", "1000", ["idle", "net"], "old")
    b = part("rt", "1000", ["idle"], "new")
    c = part("rt", "4000", ["idle", "net"], "new")
    m = rb.merge_results([("a.json", a), ("b.json", b), ("c.json", c)])
    assert list(m["kernels"]) == ["vanilla", "rt"] and list(m["kernels"]["rt"]["rates"]) == ["1000", "4000"]
    assert m["kernels"]["rt"]["rates"]["4000"]["period_us"] == 250
    assert [x["file"] for x in m["merged_from"]] == ["a.json", "b.json", "c.json"]
    assert len(rb.table_rows(m)) == 5 and m["verdict"].startswith("lower worst-case wake-up")
    assert {f["name"] for f in m["figures"]} >= {"vanilla_1khz_net_missed", "rt_4khz_net_wake_max"}
    with pytest.raises(rb.MergeError, match="rt 4000 Hz idle: in c.json and in d.json"):
        rb.merge_results([("c.json", c), ("d.json", part("rt", "4000", ["idle"], "x"))])
    with pytest.raises(rb.MergeError, match="cycles per window"):
        rb.merge_results([("a.json", a), ("b.json", {**b, "cycles_per_window": 200})])
    with pytest.raises(rb.MergeError, match="QEMU"):
        rb.merge_results([("a.json", a), ("b.json", {**b, "qemu": {"key": "other"}})])
    with pytest.raises(rb.MergeError, match="partial"):
        rb.merge_results([("a.json", {**a, "partial": True})])
    with pytest.raises(rb.MergeError, match="board zynqmp_qemu"):
        rb.merge_results([("a.json", a), ("b.json", {**b, "board": "zynqmp_qemu"})])
    assert m["board"] == "zynq7000_qemu"     # parts from before --board: the Zynq-7000's


def test_each_board_measures_its_own_kernels(rb: ModuleType) -> None:
    assert rb.board_kernels(qemu.Board.load("zynq7000_qemu")) == ("vanilla", "rt")
    assert rb.board_kernels(qemu.Board.load("zynqmp_qemu")) == ("rt",)


def _run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, str(SCRIPT), *args], capture_output=True, text=True, timeout=60, cwd=TOP)


def test_the_command_line_refuses_what_the_board_does_not_have() -> None:
    p = _run("--board", "zynqmp_qemu", "--kernels", "vanilla")
    assert p.returncode == 2 and "'vanilla' is not one of zynqmp_qemu's (rt;" in p.stderr, p.stderr
    p = _run("--board", "zynq9000_qemu")
    assert p.returncode == 2 and "no boards/zynq9000_qemu/board.yaml" in p.stderr, p.stderr


def test_the_overlay_script_knows_its_architectures() -> None:
    p = subprocess.run([str(TOP / "linux/initramfs/build-rt-tests.sh"), "--arch", "mips"],
                       capture_output=True, text=True, timeout=30)
    assert p.returncode != 0 and "--arch mips: armhf or arm64" in p.stderr, p.stderr


@pytest.mark.parametrize("board", ["zynq7000_qemu", "zynqmp_qemu"])
def test_committed_results_agree_with_their_windows(rb: ModuleType, board: str) -> None:
    path = TOP / "bench" / "results" / f"{bench.results_stem('rt_latency', board)}.json"
    if not path.exists():
        pytest.skip(f"no {path.relative_to(TOP)} yet")
    doc = json.loads(path.read_text())
    assert bench.validate(doc) == []
    assert doc.get("board", "zynq7000_qemu") == board
    assert set(doc["kernels"]) <= set(rb.board_kernels(qemu.Board.load(board)))
    if "rates" not in next(iter(doc["kernels"].values())):
        pytest.skip("results of the first figure (before the table)")
    figs = {f["name"]: f["value"] for f in doc["figures"]}
    for kernel, k in doc["kernels"].items():
        for rate, r in k["rates"].items():
            for load, w in r["windows"].items():
                key = f"{kernel}_{int(rate) // 1000}khz_{load}"
                assert figs[f"{key}_missed"] == w["missed"]
                s = w["servod_wake_ns"]
                assert s["n"] <= w["cycles"]
                if s["n"]:
                    assert s["min"] <= s["p99"] <= s["p9999"] <= s["max"]
                    assert figs[f"{key}_wake_max"] == round(s["max"] / 1000, 2)


def test_rt_latency_bench_is_mypy_strict() -> None:
    mypy = Path(sys.executable).parent / "mypy"
    p = subprocess.run([str(mypy), "--strict", str(SCRIPT)], capture_output=True, text=True, timeout=300,
                       cwd=TOP, env={"MYPYPATH": str(TOP / "python") + ":" + str(SCRIPT.parent),
                                     "PATH": "/usr/bin:/bin"})
    assert p.returncode == 0, p.stdout + p.stderr
