#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""servod's wake-up latency and cyclictest on a board's kernels, at 1 and
4 kHz, idle and with Linux loaded (issue 23, item 2; issue 35, item 5: the
ZynqMP's A53; printed, not asserted).

    .venv/bin/python bench/cycle/rt_latency_bench.py [--board zynq7000_qemu]
        [--cycles 100000] [--kernels vanilla,rt] [--rates 1000,4000]
        [--loads idle,hackbench,cpu,net,recovery]
        [--json bench/results/rt_latency.json] [--jobs 2] [--resume]
    .venv/bin/python bench/cycle/rt_latency_bench.py --merge A.json B.json... --json OUT

--board: zynq7000_qemu (the default; bench/results/rt_latency.json) or
zynqmp_qemu (bench/results/rt_latency-zynqmp_qemu.json,
python/servoamp/bench.py results_stem). The kernels are the board's
(board.yaml linux.kernels): the Zynq-7000's vanilla and PREEMPT_RT, the
ZynqMP's one 6.12 PREEMPT_RT (linux/kernel/build-zynqmp.sh).

The script is split by concern: rt_latency_table.py (percentiles, the
cyclictest parser, the table, the figures, the merge: host-side only) and
rt_latency_guest.py (the images, the telemetry reader, the windows, one
boot per kernel); this file is the command line.

``--jobs 2`` boots both kernels at once (each QEMU runs on one host core:
on two free cores the wall time halves). ``--resume`` keeps the windows an
interrupted run saved in its partial file (build/bench/rt_latency/
<json stem>.partial.json, written after every window) when it was measured
with the same --cycles, QEMU and kernel builds, and measures only the
others: the 100,000-cycle table needs about 4.7 h of one core, more than
one sitting on a shared host. Every window records its build (kernel key,
initramfs hash) and when it was measured.

For each kernel (zynq7000_qemu: linux/kernel/build.sh --variant,
SERVOAMP_KERNEL; zynqmp_qemu: its linux.build) one boot of the board on
virtual time (-icount shift=0: 1 instruction = 1 guest ns, host load does
not enter), all kernels in one run of this script. The boot's initramfs is
the board's own with the rt-tests overlay of its architecture
(linux/initramfs/build-rt-tests.sh --arch armhf|arm64: cyclictest,
hackbench and their glibc, Debian's debs) concatenated to it, in an image
and a DTB of this benchmark's own (build/bench/rt_latency/<board>/<kernel>/);
the board's images are not changed. eth0 (gem0, the board's network.nic)
is up on QEMU user networking with two forwarded ports: servod's telemetry
(7700) and a sink for the ``net`` load (5001).

servod, then rpu_app through remoteproc; per rate (``cycle_period_us`` =
1e6 / rate, set with ``ampctl param set``: servod and the firmware follow)
one window of --cycles cycles per load, in this order:

- ``idle``: nothing but the console shell (and the telemetry stream, below);
- ``hackbench``: hackbench -g 2 -l 200 in a loop (80 processes passing
  messages over socket pairs, forked again every run);
- ``cpu``: a busybox shell busy loop (SCHED_OTHER, user-space CPU hog);
- ``net``: the host sends bulk TCP through the forwarded port 5001 to a
  busybox ``nc -l`` in the guest (eth0's interrupts, the TCP receive path);
- ``recovery``: ``ampctl debug hang`` at the window's start: the firmware
  stops its cycle and heartbeat, servod's watchdog (wd_limit 50 cycles)
  reports the stall, restarts the firmware through remoteproc and restores
  the parameters; the rest of the window runs as ``idle``;
- ``fork-fs`` (not in the default list; the first figure's load): two loops
  of ``ls -R /sys``.

In every window, besides the load, cyclictest runs one SCHED_FIFO 70 thread
(below servod's cycle thread, 80, and the cycle interrupt's thread on the
RT kernel, 81) at the cycle period for the same number of loops, with a
1 us histogram (-h). On the ZynqMP Linux has one A53 (maxcpus=1), so
everything shares one CPU, as Linux's on the Zynq-7000 (CPU0; CPU1 is the
servo's).

Where each figure comes from:

- servod wake-up min / p99 / p99.99 / max: every cycle's
  ``wake_latency_ns`` (the cycle interrupt's event to servod's cycle thread
  running, read from the cycle timer's Linux counter: TTC1's on the
  Zynq-7000, the PL timer's counter 1 on the ZynqMP) in servod's
  telemetry stream, read on
  the host through the forwarded port; exact, nearest-rank percentiles over
  the records received (``records`` says how many of the window's cycles:
  a full ring drops records, announced as GAPs). The stream is on in every
  window (about 200 bytes per cycle out of eth0): it is part of every load,
  ``idle`` included;
- missed and late: servod's counters (``ampctl stats``) before and after
  the window (``linux.missed_irq``: cycle interrupts servod never saw);
  servod's own coarse histogram (buckets of linux/servod/cycle_stats.h)
  is kept in the JSON as a cross-check;
- cyclictest min / avg / max: its own summary; its p99 / p99.99: from its
  1 us histogram (the upper edge of the bucket, overflows above -h).

What this models and what not: guest ns are instructions (QEMU TCG has no
caches, no pipeline, no memory latency, and runs one instruction per ns on
either core), so the figures compare the two kernels' code paths and
preemption, not a Zynq-7000's or a ZynqMP's microseconds.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import json
import os
import platform
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "python"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from rt_latency_guest import (  # noqa: E402
    DEFAULT_LOADS, LOADS, Sender, Telemetry, bench_images, board_kernels, build_identity, run_kernel, window,
)
from rt_latency_table import (  # noqa: E402
    CT_PRIO, MergeError, figures, hist_percentile, merge_results, parse_cyclictest, percentile, table_markdown,
    table_rows, verdict, wake_summary,
)
from servoamp import qemu  # noqa: E402
from servoamp.bench import results_stem  # noqa: E402

__all__ = [
    "CT_PRIO", "DEFAULT_LOADS", "LOADS", "MergeError", "Sender", "Telemetry", "bench_images", "board_kernels",
    "build_identity", "figures", "hist_percentile", "merge_results", "parse_cyclictest", "percentile",
    "run_kernel", "table_markdown", "table_rows", "verdict", "wake_summary", "window",
]


def kill_children_and_exit(signum: int, frame: Any) -> None:
    """SIGTERM / SIGHUP: the QEMUs this run started die with it (orphaned,
    each would go on at 100 % of a host core); the windows saved so far
    stay in the partial file for --resume."""
    me = os.getpid()
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            ppid = int(stat.read_text().rsplit(")", 1)[1].split()[1])
            if ppid == me:
                os.kill(int(stat.parent.name), signal.SIGKILL)
        except (OSError, IndexError, ValueError):
            continue
    os._exit(128 + signum)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cycles", type=int, default=10_000,
                    help="cycles per window and rate (default: %(default)s; the committed results: 100000)")
    ap.add_argument("--board", default="zynq7000_qemu",
                    help="the board folder under boards/ (default: %(default)s)")
    ap.add_argument("--kernels", default=None,
                    help="the board's kernels to boot (default: every one of its linux.kernels: "
                         "zynq7000_qemu vanilla,rt, zynqmp_qemu rt)")
    ap.add_argument("--rates", default="1000,4000", help="cycle rates in Hz (default: %(default)s)")
    ap.add_argument("--loads", default=",".join(DEFAULT_LOADS))
    ap.add_argument("--json", type=Path, default=None,
                    help="results (default: bench/results/rt_latency.json for zynq7000_qemu, "
                         "rt_latency-<board>.json for another board)")
    ap.add_argument("--jobs", type=int, default=1,
                    help="kernels booted at once (each QEMU runs on one host core; default: %(default)s)")
    ap.add_argument("--resume", action="store_true",
                    help="keep the windows of an interrupted run of the same --json (its partial file in "
                         "build/bench/rt_latency/), measured with the same --cycles, QEMU and kernel builds, "
                         "and measure only the others")
    ap.add_argument("--merge", type=Path, nargs="+", metavar="RESULTS",
                    help="measure nothing: write one table (--json) from the results files of separate "
                         "runs (each window from one of them) and print it")
    args = ap.parse_args()
    if args.merge:
        try:
            merged = merge_results([(str(p), json.loads(p.read_text())) for p in args.merge])
        except (MergeError, OSError, json.JSONDecodeError) as e:
            ap.error(f"--merge: {e}")
        print(table_markdown(merged))
        print(f"\n{merged['verdict']}")
        if args.json is None:
            ap.error("--merge needs --json OUT")
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(merged, indent=2) + "\n")
        print(f"written {args.json}")
        return 0
    if args.jobs < 1:
        ap.error("--jobs: at least 1")
    for sig in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, kill_children_and_exit)
    loads = args.loads.split(",")
    for name in loads:
        if name not in LOADS:
            ap.error(f"--loads: {name!r} is not one of {', '.join(LOADS)}")
    rates = [int(x) for x in args.rates.split(",")]
    for rate in rates:
        if 1_000_000 % rate or not 100 <= rate <= 8000:
            ap.error(f"--rates: {rate} Hz is not a whole number of us in 125..10000 us")
    if not (REPO / "boards" / args.board / "board.yaml").exists():
        ap.error(f"--board {args.board}: no boards/{args.board}/board.yaml")
    board = qemu.Board.load(args.board)
    own = board_kernels(board)
    kernels = args.kernels.split(",") if args.kernels else list(own)
    for kernel in kernels:
        if kernel not in own:
            ap.error(f"--kernels: {kernel!r} is not one of {board.name}'s ({', '.join(own)}; "
                     f"boards/{board.name}/board.yaml linux.kernels)")
    if args.json is None:
        args.json = REPO / "bench" / "results" / f"{results_stem('rt_latency', board.name)}.json"
    result: dict[str, Any] = {
        "command": "bench/cycle/rt_latency_bench.py " + " ".join(sys.argv[1:]),
        "host": {"cpus": os.cpu_count(), "load_avg_at_start": os.getloadavg(), "machine": platform.machine()},
        "board": board.name,
        "qemu": qemu.check_qemu(board),
        "note": "virtual time (-icount shift=0): guest ns are instructions; no caches. servod wake-up "
                "min/p99/p99.99/max: per-cycle wake_latency_ns from servod's telemetry stream (on in every "
                "window); missed/late: servod's counters; cyclictest: its own min/avg/max and its 1 us "
                "histogram (p99/p99.99 = upper bucket edge)",
        "cycles_per_window": args.cycles,
        "kernels": {},
    }
    args.json.parent.mkdir(parents=True, exist_ok=True)
    partial = REPO / "build/bench/rt_latency" / (args.json.stem + ".partial.json")  # not in bench/results
    partial.parent.mkdir(parents=True, exist_ok=True)

    lock = threading.Lock()

    def save(k: dict[str, Any]) -> None:
        with lock:
            result["kernels"][k["kernel"]] = k
            partial.write_text(json.dumps({**result, "partial": True}, indent=2) + "\n")

    # the images first, one kernel after the other (the build steps share
    # build/ and the environment), then the boots, --jobs at a time
    images = {k: bench_images(board, k, REPO / "build/bench/rt_latency" / board.name / k) for k in kernels}
    done: dict[str, Any] = {}
    if args.resume and partial.exists():
        old = json.loads(partial.read_text())
        for kernel in kernels:
            k = old.get("kernels", {}).get(kernel)
            if not k:
                continue
            same = (old.get("cycles_per_window") == args.cycles and old.get("qemu") == result["qemu"]
                    and k.get("build", {}).get("kernel_key") == build_identity(kernel, images[kernel])["kernel_key"])
            n = sum(len(r.get("windows", {})) for r in k.get("rates", {}).values())
            print(f"[{kernel:7}] resume: {n} windows in {partial}: "
                  + ("kept" if same else "not kept (other --cycles, QEMU or kernel build)"), flush=True)
            if same:
                done[kernel] = k
        result["resumed_from"] = {"partial": str(partial), "started": old.get("started"),
                                  "kernels": sorted(done)}
        # the kept windows stay in the partial file whichever kernel saves
        # next (they were lost when the other kernel's job saved first)
        result["kernels"].update(done)
    result["started"] = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    with concurrent.futures.ThreadPoolExecutor(max_workers=args.jobs) as pool:
        futures = {k: pool.submit(run_kernel, board, k, images[k], args.cycles, rates, loads, save, done.get(k))
                   for k in kernels}
        for kernel in kernels:
            result["kernels"][kernel] = futures[kernel].result()
    result["verdict"] = verdict(result)
    print(f"\n{args.cycles} cycles per window (virtual time; guest ns = instructions); servod columns in us "
          "from its telemetry, cyclictest in us from its own output\n")
    print(table_markdown(result))
    print(f"\n{result['verdict']}")
    result["figures"] = figures(result)
    args.json.write_text(json.dumps(result, indent=2) + "\n")
    partial.unlink(missing_ok=True)
    print(f"written {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
