# SPDX-License-Identifier: MIT
"""The RT latency table's host-side computations (bench/cycle/
rt_latency_bench.py; tests/bench/test_rt_latency_bench.py): nearest-rank
percentiles, cyclictest's output and histogram, the Markdown table, the
figures of bench/figures.schema.json, the verdict between kernels and the
merge of separate runs into one table. Nothing here boots a guest."""

from __future__ import annotations

import math
import re
from typing import Any, Mapping, Sequence

CT_PRIO = 70        # cyclictest's SCHED_FIFO priority (below servod's 80, the IRQ thread's 81)


def percentile(sorted_values: Sequence[int], p: float) -> int | None:
    """Nearest-rank percentile (the smallest value with at least p % of the
    values at or below it) of an ascending sequence; None when empty."""
    n = len(sorted_values)
    if n == 0:
        return None
    rank = max(1, math.ceil(p / 100.0 * n))
    return int(sorted_values[min(rank, n) - 1])


def hist_percentile(hist: Mapping[int, int], overflows: int, p: float) -> int | None:
    """The p-th percentile of a cyclictest histogram (bucket us -> count;
    bucket b holds latencies in [b, b+1) us): the upper edge b+1 of the
    bucket that holds the nearest-rank sample; None when the rank falls in
    the overflows (above the histogram) or there are no samples."""
    total = sum(hist.values()) + overflows
    if total == 0:
        return None
    rank = max(1, math.ceil(p / 100.0 * total))
    seen = 0
    for b in sorted(hist):
        seen += hist[b]
        if seen >= rank:
            return b + 1
    return None


def parse_cyclictest(text: str) -> dict[str, Any]:
    """cyclictest -q -h N output (one thread): its min/avg/max (us), the
    non-empty histogram buckets, overflows, samples."""
    hist: dict[int, int] = {}
    out: dict[str, Any] = {}
    for line in text.splitlines():
        m = re.match(r"^(\d{6})\s+(\d+)\s*$", line)
        if m:
            if int(m.group(2)):
                hist[int(m.group(1))] = int(m.group(2))
            continue
        m = re.match(r"^# (Min|Avg|Max) Latencies:\s+(\d+)", line)
        if m:
            out[m.group(1).lower()] = int(m.group(2))
            continue
        m = re.match(r"^# Histogram Overflows:\s+(\d+)", line)
        if m:
            out["overflows"] = int(m.group(1))
        m = re.match(r"^# Total:\s+(\d+)", line)
        if m:
            out["samples"] = int(m.group(1))
    out["histogram_us"] = {str(k): v for k, v in sorted(hist.items())}
    out.setdefault("overflows", 0)
    out.setdefault("samples", sum(hist.values()) + out["overflows"])
    for p, k in ((99.0, "p99"), (99.99, "p9999")):
        out[k] = hist_percentile(hist, out["overflows"], p)
    return out


def wake_summary(values_ns: Sequence[int]) -> dict[str, Any]:
    """min / p50 / p99 / p99.99 / max / mean (ns) of the window's wake-up latencies."""
    v = sorted(values_ns)
    if not v:
        return {"n": 0}
    return {"n": len(v), "min": v[0], "p50": percentile(v, 50), "p99": percentile(v, 99),
            "p9999": percentile(v, 99.99), "max": v[-1], "mean": round(sum(v) / len(v), 1)}


def _us(ns: float | None) -> str:
    return "-" if ns is None else f"{ns / 1000:.1f}"


def _ct(v: Any) -> str:
    return "-" if v is None else str(v)


def table_rows(result: Mapping[str, Any]) -> list[list[str]]:
    """One row per kernel, rate and load: the table of docs/cycle.md."""
    rows = []
    for kernel, k in result["kernels"].items():
        for rate, r in k["rates"].items():
            for load, w in r["windows"].items():
                s, ct = w["servod_wake_ns"], w["cyclictest"]
                rows.append([
                    kernel, f"{int(rate) // 1000} kHz", load, str(w["cycles"]),
                    f"{s.get('n', 0)}", str(w["missed"]),
                    _us(s.get("min")), _us(s.get("p99")), _us(s.get("p9999")), _us(s.get("max")),
                    f"{_ct(ct.get('min'))} / {_ct(ct.get('avg'))} / {_ct(ct.get('max'))}",
                    f"{_ct(ct.get('p99'))} / {_ct(ct.get('p9999'))}",
                ])
    return rows


TABLE_HEAD = ["kernel", "rate", "load", "cycles", "records", "missed",
              "servod min", "p99", "p99.99", "max",
              "cyclictest min / avg / max", "cyclictest p99 / p99.99"]


def table_markdown(result: Mapping[str, Any]) -> str:
    """The table as Markdown (servod columns in us from the telemetry
    records; cyclictest in its own whole us)."""
    lines = ["| " + " | ".join(TABLE_HEAD) + " |",
             "|" + "|".join("---" if i < 3 else "---:" for i in range(len(TABLE_HEAD))) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in table_rows(result)]
    return "\n".join(lines)


def figures(result: Mapping[str, Any]) -> list[dict[str, Any]]:
    """The summary table's figures (bench/README.md, bench/figures.schema.json)."""
    out: list[dict[str, Any]] = []
    for kernel, k in result["kernels"].items():
        for rate, r in k["rates"].items():
            for load, w in r["windows"].items():
                key = f"{kernel}_{int(rate) // 1000}khz_{load}"
                s, ct = w["servod_wake_ns"], w["cyclictest"]
                out.append({"name": f"{key}_missed", "value": w["missed"], "unit": "cycles",
                            "better": "lower", "note": f"servod's linux.missed_irq over {w['cycles']} cycles"})
                for q in ("p99", "p9999", "max"):
                    if s.get(q) is not None:
                        out.append({"name": f"{key}_wake_{q}", "value": round(s[q] / 1000, 2), "unit": "us",
                                    "better": "lower",
                                    "note": f"servod wake-up, telemetry, {s['n']} of {w['cycles']} cycles"})
                if ct.get("max") is not None:
                    out.append({"name": f"{key}_cyclictest_max", "value": ct["max"], "unit": "us",
                                "better": "lower", "note": f"cyclictest FIFO {CT_PRIO} at the cycle period, "
                                                          f"{ct.get('samples')} loops"})
    return out


def verdict(result: Mapping[str, Any]) -> str:
    """Which kernel the figures favour: the lower worst servod wake-up max
    under load, then fewer misses."""
    ks = result["kernels"]
    if len(ks) < 2:
        return "one kernel measured: no comparison"
    score: dict[str, tuple[int, float]] = {}
    for kernel, k in ks.items():
        missed = sum(w["missed"] for r in k["rates"].values() for w in r["windows"].values())
        worst = max((w["servod_wake_ns"].get("max") or 0) for r in k["rates"].values()
                    for w in r["windows"].values())
        score[kernel] = (missed, worst)
    parts = [f"{k}: {m} missed, worst wake-up {w / 1000:.1f} us" for k, (m, w) in score.items()]
    best = min(score, key=lambda k: (score[k][1], score[k][0]))
    return f"lower worst-case wake-up: {best} ({'; '.join(parts)})"


class MergeError(ValueError):
    """Parts that do not make one table."""


def merge_results(parts: Sequence[tuple[str, Mapping[str, Any]]]) -> dict[str, Any]:
    """One table from the results files of separate runs (``--merge``): a
    kernel's rates taken apart and measured at once on two host cores, or
    the windows of a kernel measured again after a change that concerns
    only that kernel. ``parts`` are (file name, its JSON). The parts must
    agree on the cycles per window and the QEMU build; each (kernel, rate,
    load) window may come from one part only. A kernel's own entries (its
    release, thread table, build) come from the first part that has it;
    every window keeps the build it was measured with. The sources are
    listed in ``merged_from``; verdict and figures are computed again."""
    if not parts:
        raise MergeError("nothing to merge")
    first = parts[0][1]
    out: dict[str, Any] = {
        "command": "bench/cycle/rt_latency_bench.py --merge " + " ".join(n for n, _ in parts),
        "board": first.get("board", "zynq7000_qemu"),
        "host": first.get("host"), "qemu": first.get("qemu"), "note": first.get("note"),
        "cycles_per_window": first.get("cycles_per_window"), "kernels": {}, "merged_from": [],
    }
    origin: dict[tuple[str, str, str], str] = {}
    for name, doc in parts:
        if doc.get("partial"):
            raise MergeError(f"{name}: a partial file (an interrupted run): finish it with --resume first")
        if doc.get("cycles_per_window") != out["cycles_per_window"]:
            raise MergeError(f"{name}: {doc.get('cycles_per_window')} cycles per window, "
                             f"{parts[0][0]}: {out['cycles_per_window']}")
        if doc.get("board", "zynq7000_qemu") != out["board"]:
            raise MergeError(f"{name}: board {doc.get('board', 'zynq7000_qemu')}, {parts[0][0]}: {out['board']}")
        if doc.get("qemu") != out["qemu"]:
            raise MergeError(f"{name}: another QEMU build than {parts[0][0]}'s")
        out["merged_from"].append({"file": name, "command": doc.get("command"), "started": doc.get("started"),
                                   "kernels": sorted(doc.get("kernels", {}))})
        for kernel, k in doc.get("kernels", {}).items():
            dst = out["kernels"].setdefault(kernel, {**{x: v for x, v in k.items() if x != "rates"}, "rates": {}})
            for rate, r in k.get("rates", {}).items():
                dr = dst["rates"].setdefault(rate, {**{x: v for x, v in r.items() if x != "windows"},
                                                    "windows": {}})
                for load, w in r.get("windows", {}).items():
                    key = (kernel, rate, load)
                    if key in origin:
                        raise MergeError(f"{kernel} {rate} Hz {load}: in {origin[key]} and in {name}")
                    origin[key] = name
                    dr["windows"][load] = w
    out["verdict"] = verdict(out)
    out["figures"] = figures(out)
    return out
