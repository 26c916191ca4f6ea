#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""Is the emulated cycle independent of the host? The same scenario, three
boots under virtual time (-icount): twice on a quiet host, once with a busy
process on every host core.

    .venv/bin/python bench/cycle/determinism_bench.py [--cycles 8000]
        [--period-us 1000] [--runs quiet,quiet,loaded]
        [--json bench/results/determinism.json]

Each run boots zynq7000_qemu with guest networking, starts servod and
rpu_app, records servod's telemetry (every cycle) to MCAP until --cycles
cycles are on record, and summarises the recording with `servoamp info`'s
code: cycles, missed cycles (both sides), the servo's interrupt entry
latency (irq_latency: from the TTC1 interval event to the handler, in guest
ns) and servod's wake-up latency (UIO event to servod running), p50 / p99 /
max over the same number of cycles. Figures are compared against the
first run of the same invocation (ratio).

Under virtual time guest time counts instructions, so host load changes
only how long the run takes in host seconds. What can still differ between
runs is where host input lands in guest time: the shell commands typed on
the console and the TCP segments of the telemetry stream arrive at host
moments, become guest interrupts at different instructions, and move the
guest's scheduling by a few microseconds.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "python"))

from servoamp import info, netboard, qemu, record  # noqa: E402

from cycle_bench import run_info  # noqa: E402  (same folder)


def _busy() -> None:
    while True:
        pass


class HostLoad:
    """One busy process per host core for the duration of a ``with``."""

    def __init__(self, active: bool) -> None:
        self.active = active
        self.procs: list[multiprocessing.Process] = []

    def __enter__(self) -> HostLoad:
        if self.active:
            for _ in range(os.cpu_count() or 1):
                p = multiprocessing.Process(target=_busy, daemon=True)
                p.start()
                self.procs.append(p)
        return self

    def __exit__(self, *exc: Any) -> None:
        for p in self.procs:
            p.terminate()
        for p in self.procs:
            p.join()


def run_once(board: qemu.Board, images: qemu.Images, cycles: int, period_us: int, loaded: bool,
             workdir: Path, name: str) -> dict[str, Any]:
    out = workdir / f"{name}.mcap"
    with HostLoad(loaded), netboard.ControllerBoard(board, images, clock="virtual") as cb:
        t0 = time.monotonic()
        cb.start_servod()
        cb.start_firmware()
        cb.sh("ampctl param set wd_limit 50; ampctl resume; true")
        if period_us != 1000:
            cb.sh(f"ampctl param set cycle_period_us {period_us}")
        stop = threading.Event()

        def progress(r: record.RecordResult) -> None:
            if r.cycles >= cycles:
                stop.set()

        res = record.record("127.0.0.1", cb.host_port, out, None, stop=stop, on_progress=progress,
                            connect_timeout=30.0, token=cb.token)
        host_s = time.monotonic() - t0
        stats = cb.stats()
    s = info.summarize(out)
    return {
        "host_load": "a busy process per host core" if loaded else "none added",
        "host_seconds": round(host_s, 1),
        "cycles_on_record": s["cycles"],
        "gaps": len(s["gaps"]),
        "missed_on_record": s["missed"],
        "linux_missed_irq": int(stats.get("linux.missed_irq", "-1")),
        "servo_missed": int(stats.get("servo.missed", "-1")),
        "linux_cycles": int(stats.get("linux.cycles", "-1")),
        "servo_cycles": int(stats.get("servo.cycles", "-1")),
        "irq_latency_ns": s["irq_latency_ns"],
        "wake_latency_ns": s["wake_latency_ns"],
    }


def figures(result: dict[str, Any]) -> list[dict[str, Any]]:
    """The summary table's figures (bench/README.md); targets in bench/targets.toml."""
    runs = result["runs"]
    kinds = ",".join(r["kind"] for r in runs)
    out: list[dict[str, Any]] = [
        {"name": "missed_total", "unit": "cycles", "better": "lower",
         "value": sum(r["linux_missed_irq"] + r["servo_missed"] for r in runs),
         "note": f"both sides, runs {kinds}"},
        {"name": "gaps_total", "unit": "gaps", "better": "lower", "value": sum(r["gaps"] for r in runs),
         "note": f"{sum(r['cycles_on_record'] for r in runs)} cycles on record"},
    ]
    for key, name in (("irq_latency_ns", "irq"), ("wake_latency_ns", "wake")):
        p99 = [r[key]["p99"] for r in runs]
        out.append({"name": f"{name}_p99_spread", "unit": "ns", "better": "lower",
                    "value": max(p99) - min(p99), "note": f"max-min of p99 over runs ({min(p99):.0f} ns)"})
        mx = [r[key]["max"] for r in runs]
        out.append({"name": f"{name}_max", "unit": "ns", "better": "lower", "value": max(mx),
                    "spread": {"min": min(mx), "max": max(mx)}, "note": "over runs"})
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cycles", type=int, default=8000)
    ap.add_argument("--period-us", type=int, default=1000)
    ap.add_argument("--runs", default="quiet,quiet,loaded")
    ap.add_argument("--json", type=Path, default=REPO / "bench/results/determinism.json")
    args = ap.parse_args()
    board = qemu.Board.load("zynq7000_qemu")
    images = qemu.prepare_images(board)
    result: dict[str, Any] = {
        **run_info(board, "determinism_bench.py"),
        "clock": " ".join(qemu.clock_args(board, "virtual")),
        "cycles": args.cycles, "period_us": args.period_us,
        "runs": [],
    }
    with tempfile.TemporaryDirectory(prefix="servoamp-det-") as tmp:
        for i, kind in enumerate(args.runs.split(",")):
            if kind not in ("quiet", "loaded"):
                ap.error(f"--runs: {kind!r} is not quiet or loaded")
            r = run_once(board, images, args.cycles, args.period_us, kind == "loaded", Path(tmp), f"run{i}")
            result["runs"].append({"kind": kind, **r})
            print(f"[run {i} {kind:6}] host {r['host_seconds']} s, {r['cycles_on_record']} cycles on record, "
                  f"missed linux {r['linux_missed_irq']} servo {r['servo_missed']} (of {r['linux_cycles']}/"
                  f"{r['servo_cycles']}), gaps {r['gaps']}", flush=True)
    base = result["runs"][0]
    print(f"\n{'run':<10} {'host s':>7} {'missed':>7} " + " ".join(
        f"{w + ' ' + q:>16}" for w in ("irq", "wake") for q in ("p50", "p99", "max")))
    for i, r in enumerate(result["runs"]):
        cells = []
        for w in ("irq_latency_ns", "wake_latency_ns"):
            for q in ("p50", "p99", "max"):
                v, b = r[w][q], base[w][q]
                cells.append(f"{v:>9.0f} ({v / b if b else 0:4.2f})")
        miss = r["linux_missed_irq"] + r["servo_missed"]
        print(f"{str(i) + ' ' + r['kind']:<10} {r['host_seconds']:>7} {miss:>7} " + " ".join(f"{c:>16}" for c in cells))
    print("(guest ns; in brackets: ratio to run 0)")
    result["figures"] = figures(result)
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(result, indent=2) + "\n")
    print(f"written {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
