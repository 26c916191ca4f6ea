#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""servod's wake-up latency on both kernels, idle and with Linux loaded
(issue 23: a first figure, printed, not asserted by any test).

    .venv/bin/python bench/cycle/rt_latency_bench.py [--seconds 5]
        [--kernels default,rt] [--loads idle,cpu,fork-fs]
        [--json bench/results/rt_latency.json]

For each kernel (linux/kernel/build.sh --variant; SERVOAMP_KERNEL) one boot
of zynq7000_qemu on virtual time (-icount shift=0: 1 instruction = 1 guest
ns, host load does not enter): servod, then rpu_app through remoteproc, the
exchange at 1 ms, then one window of --seconds guest seconds per load, in
this order:

- ``idle``: nothing but the console shell;
- ``cpu``: a busybox shell busy loop (SCHED_OTHER, user-space CPU hog);
- ``fork-fs``: two busybox loops of ``ls -R /sys`` (fork, exec, sysfs walks:
  long stretches in the kernel, where the default kernel does not preempt).

Per window: Linux cycles and missed cycle interrupts, late cycles, the
histogram of servod's wake-up latency (the interrupt event to servod
running, read from TTC1's counter; buckets of linux/servod/cycle_stats.h)
and the largest bucket reached; servod's min/mean/max are since its start
(the max after a window is the max over it and every earlier one).

What this models and what not: guest ns are instructions (QEMU TCG has no
caches, no pipeline, no memory latency), so the figures compare the two
kernels' code paths, not a Zynq-7000's microseconds. hackbench and
cyclictest (rt-tests, glibc) are not in the initramfs yet: the loads are
busybox stand-ins.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "python"))

from servoamp import qemu  # noqa: E402

from cycle_bench import run_info, stats  # noqa: E402  (same folder)

LOADS: dict[str, list[str]] = {
    "idle": [],
    "cpu": ["while :; do :; done"],
    "fork-fs": ["while :; do ls -R /sys >/dev/null 2>&1; done"] * 2,
}


def window(sh: Any, console: qemu.Uart, prompt: str, seconds: float, load: list[str]) -> dict[str, Any]:
    for loop in load:
        sh(f"({loop}) >/dev/null 2>&1 & echo $! >> /tmp/load.pids")
    a = stats(console, prompt)
    t0 = time.monotonic()
    sh(f"sleep {seconds}", seconds * 60 + 60)
    host = time.monotonic() - t0
    b = stats(console, prompt)
    if load:
        sh("kill $(cat /tmp/load.pids); rm -f /tmp/load.pids; sleep 0.2")

    def delta(k: str) -> int:
        return int(b[k], 0) - int(a.get(k, "0"), 0)

    hist = {k.split(".", 2)[2]: delta(k) for k in b if k.startswith("linux.wake_lat_hist.")}
    reached = [k for k, v in hist.items() if v]
    return {
        "guest_seconds": seconds,
        "host_seconds": round(host, 1),
        "cycles": delta("linux.cycles"),
        "missed": delta("linux.missed_irq"),
        "late": delta("linux.late"),
        "wake_latency_histogram": hist,
        "largest_bucket_reached": reached[-1] if reached else None,
        "wake_latency_ns_since_start": {k: int(b[f"linux.wake_lat_ns.{k}"], 0) for k in ("min", "mean", "max")},
    }


def run_kernel(board: qemu.Board, kernel: str, seconds: float, loads: list[str]) -> dict[str, Any]:
    os.environ["SERVOAMP_KERNEL"] = kernel
    images = qemu.prepare_images(board)
    prompt = str(board.data["linux"]["prompt"])
    m = qemu.QemuMachine(board, images, accel="tcg,thread=single", clock="virtual")
    out: dict[str, Any] = {"kernel": kernel, "kernelrelease": "", "windows": {}}
    with m:
        qemu.boot_to_shell(m, timeout=120)
        c = m.uart(0)

        def sh(cmd: str, t: float = 60.0) -> str:
            rc, text = qemu.run_shell(c, cmd, prompt, timeout=t)
            if rc:
                raise RuntimeError(f"{cmd!r} failed ({rc}):\n{text}")
            return str(text)

        out["kernelrelease"] = sh("uname -r").strip()
        sh("dmesg -n 1")
        sh("(servod > /tmp/servod.log 2>&1 &)")
        sh("while ! grep -q 'waiting for the servo' /tmp/servod.log; do sleep 0.05; done")
        sh("echo rpu_app.elf > /sys/class/remoteproc/remoteproc0/firmware; "
           "echo start > /sys/class/remoteproc/remoteproc0/state")
        sh("while ! grep -q 'parameter set loaded' /tmp/servod.log; do sleep 0.05; done")
        sh("ampctl param set wd_limit 50; ampctl resume; true")
        # every real-time thread (interrupt threads, servod's cycle thread,
        # the kernel's own): name, rt_priority, policy (stat fields 40, 41;
        # 1 = SCHED_FIFO)
        out["threads"] = sh("for p in /proc/[0-9]*/task/[0-9]*; do s=$(cut -d' ' -f40,41 $p/stat 2>/dev/null); "
                            "case $s in ''|*' 0') ;; *) echo \"$(cat $p/comm) $s\";; esac; done; true")
        for name in loads:
            out["windows"][name] = window(sh, c, prompt, seconds, LOADS[name])
            w = out["windows"][name]
            print(f"[{kernel:7} {name:8}] cycles {w['cycles']} missed {w['missed']} late {w['late']}, "
                  f"wake-up: largest bucket {w['largest_bucket_reached']}, since start "
                  f"{w['wake_latency_ns_since_start']} ns ({w['host_seconds']} s host)", flush=True)
    return out


def figures(result: dict[str, Any]) -> list[dict[str, Any]]:
    """The summary table's figures (bench/README.md, bench/figures.schema.json)."""
    out: list[dict[str, Any]] = []
    for kernel, k in result["kernels"].items():
        for name, w in k["windows"].items():
            lat = w["wake_latency_ns_since_start"]
            out += [
                {"name": f"{kernel}_{name}_missed", "value": w["missed"], "unit": "cycles", "better": "lower",
                 "note": f"of {w['cycles'] + w['missed']} in {w['guest_seconds']} s guest time"},
                {"name": f"{kernel}_{name}_wake_latency_max", "value": round(lat["max"] / 1000, 2), "unit": "us",
                 "better": "lower", "note": f"since servod's start; largest bucket of the window: "
                                            f"{w['largest_bucket_reached']}"},
                {"name": f"{kernel}_{name}_wake_latency_mean", "value": round(lat["mean"] / 1000, 2),
                 "unit": "us", "better": "lower", "note": "since servod's start"},
            ]
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=5.0, help="guest seconds per window (default: %(default)s)")
    ap.add_argument("--kernels", default="default,rt")
    ap.add_argument("--loads", default=",".join(LOADS))
    ap.add_argument("--json", type=Path, default=REPO / "bench/results/rt_latency.json")
    args = ap.parse_args()
    loads = args.loads.split(",")
    for name in loads:
        if name not in LOADS:
            ap.error(f"--loads: {name!r} is not one of {', '.join(LOADS)}")
    board = qemu.Board.load("zynq7000_qemu")
    result: dict[str, Any] = {
        **run_info(board, "rt_latency_bench.py"),
        "note": "virtual time (-icount shift=0): guest ns are instructions; no caches; "
                "busybox loads, not hackbench",
        "kernels": {},
    }
    for kernel in args.kernels.split(","):
        if kernel not in qemu.KERNELS:
            ap.error(f"--kernels: {kernel!r} is not one of {', '.join(qemu.KERNELS)}")
        result["kernels"][kernel] = run_kernel(board, kernel, args.seconds, loads)

    print(f"\nservod wake-up latency, 1 ms cycle, {args.seconds:g} guest s per window "
          "(virtual time; guest ns = instructions)")
    print(f"{'kernel':8} {'load':8} {'cycles':>7} {'missed':>6} {'late':>5}  {'largest bucket':15} "
          f"{'max since start (us)':>20}")
    for kernel, k in result["kernels"].items():
        for name, w in k["windows"].items():
            print(f"{kernel:8} {name:8} {w['cycles']:7} {w['missed']:6} {w['late']:5}  "
                  f"{str(w['largest_bucket_reached']):15} {w['wake_latency_ns_since_start']['max'] / 1000:20.1f}")
    result["figures"] = figures(result)
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(result, indent=2) + "\n")
    print(f"written {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
