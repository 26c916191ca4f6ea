#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""Figures of the cycle on the emulated board (QEMU), one boot per mode.

    .venv/bin/python bench/cycle/cycle_bench.py [--seconds 10] [--short 3]
        [--modes virtual,host-single,host-multi] [--json bench/results/cycle.json]

Modes: ``virtual`` (the default: -icount, guest time counts instructions,
single-threaded TCG; every figure is in guest ns, independent of host
load), ``host-single`` and ``host-multi`` (guest time on the host clock,
single- or multi-threaded TCG: figures depend on the host's load).

Boots zynq7000_qemu, starts servod, then rpu_app through remoteproc, and
runs the exchange for --seconds at 1 ms and --short at 250 us. Prints and
stores, per period: cycles and missed cycles on each side, exchange
counters, the per-cycle cost of the exchange on each side (servo: A9
global-timer ticks of 10 ns from the cycle handler's entry to commands
consumed / control / feedback published; Linux: wake-up to commands
published, CLOCK_MONOTONIC), the servo's interrupt entry latency and
servod's wake-up latency histogram (interrupt event to servod running,
read from its own TTC counter).

QEMU is not cycle-accurate: these figures describe the emulator on this
host (TCG, shared machine), not a Zynq-7000.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "python"))

from servoamp import qemu  # noqa: E402

# mode -> (guest clock, QEMU -accel)
MODES: dict[str, tuple[str, str | None]] = {
    "virtual": ("virtual", "tcg,thread=single"),
    "host-single": ("host", "tcg,thread=single"),
    "host-multi": ("host", None),
}


def stats(console: qemu.Uart, prompt: str) -> dict[str, str]:
    rc, out = qemu.run_shell(console, "ampctl stats", prompt, timeout=30)
    if rc:
        raise RuntimeError(f"ampctl stats failed ({rc}):\n{out}")
    return {l.split("=", 1)[0]: l.split("=", 1)[1] for l in out.splitlines() if "=" in l}


def window(console: qemu.Uart, prompt: str, seconds: float) -> dict[str, object]:
    a = stats(console, prompt)
    t0 = time.monotonic()
    qemu.run_shell(console, f"sleep {seconds}", prompt, timeout=seconds * 10 + 30)
    host = time.monotonic() - t0
    b = stats(console, prompt)
    d = {}
    for k, v in b.items():
        try:
            d[k] = int(v, 0) - int(a.get(k, "0"), 0) if not k.startswith(("linux.wake_lat_ns", "linux.work_ns", "servo.")) or k in (
                "servo.cycles", "servo.missed", "servo.cmd_fresh", "servo.cmd_stale", "servo.cmd_torn",
                "servo.cmd_missed", "servo.cmd_invalid") else int(v, 0)
        except ValueError:
            d[k] = v
    lin = d["linux.cycles"] + d["linux.missed_irq"]
    res: dict[str, object] = {
        "guest_seconds": seconds,
        "host_seconds": round(host, 2),
        "linux": {
            "cycles": d["linux.cycles"], "missed": d["linux.missed_irq"],
            "miss_rate_pct": round(100.0 * d["linux.missed_irq"] / max(1, lin), 3),
            "late_cycles": d["linux.late"],
            "feedback": {k: d[f"linux.fb_{k}"] for k in ("fresh", "stale", "torn", "missed", "invalid")},
            "work_ns_wake_to_published": {"mean": d["linux.work_ns.mean"], "max_since_start": d["linux.work_ns.max"]},
            "wake_latency_ns_since_start": {k: d[f"linux.wake_lat_ns.{k}"] for k in ("min", "mean", "max")},
            "wake_latency_histogram_window": {k.split(".", 2)[2]: v for k, v in d.items() if k.startswith("linux.wake_lat_hist.")},
        },
        "servo": {
            "cycles": d["servo.cycles"], "missed": d["servo.missed"],
            "miss_rate_pct": round(100.0 * d["servo.missed"] / max(1, d["servo.cycles"] + d["servo.missed"]), 3),
            "commands": {k: d[f"servo.cmd_{k}"] for k in ("fresh", "stale", "torn", "missed", "invalid")},
            "cost_ticks_10ns_since_start": {
                p: {"mean": d[f"servo.{p}_ticks.mean"], "max": d[f"servo.{p}_ticks.max"]}
                for p in ("rx", "ctrl", "tx", "cycle")},
            "irq_entry_latency_ns_max_since_start": d["servo.irq_lat_ns.max"],
            "axes": d["servo.axes"],
        },
    }
    return res


def run_mode(board: qemu.Board, images: qemu.Images, clock: str, accel: str | None, seconds: float,
             short: float) -> dict[str, object]:
    prompt = str(board.data["linux"]["prompt"])
    m = qemu.QemuMachine(board, images, accel=accel, clock=clock)
    with m:
        qemu.boot_to_shell(m, timeout=90)
        c = m.uart(0)
        sh = lambda cmd, t=60.0: qemu.run_shell(c, cmd, prompt, timeout=t)  # noqa: E731
        sh("dmesg -n 1")
        sh("(servod > /tmp/servod.log 2>&1 &)")
        sh("while ! grep -q 'waiting for the servo' /tmp/servod.log; do sleep 0.05; done")
        sh("echo rpu_app.elf > /sys/class/remoteproc/remoteproc0/firmware; echo start > /sys/class/remoteproc/remoteproc0/state")
        sh("while ! grep -q 'parameter set loaded' /tmp/servod.log; do sleep 0.05; done")
        sh("ampctl param set wd_limit 50; ampctl resume; true")
        out: dict[str, object] = {}
        out["1000us"] = window(c, prompt, seconds)
        sh("ampctl param set cycle_period_us 250; sleep 0.2")
        out["250us"] = window(c, prompt, short)
        sh("ampctl param set cycle_period_us 1000")
        return out


def run_info(board: qemu.Board, script: str) -> dict[str, object]:
    """What every cycle benchmark's JSON starts with: the command, the host
    and the QEMU binary."""
    return {
        "command": f"bench/cycle/{script} " + " ".join(sys.argv[1:]),
        "host": {"cpus": os.cpu_count(), "load_avg_at_start": os.getloadavg(), "machine": platform.machine()},
        "qemu": qemu.check_qemu(board),
    }


def figures(result: dict[str, Any]) -> list[dict[str, Any]]:
    """The summary table's figures (bench/README.md); targets in bench/targets.toml."""
    out: list[dict[str, Any]] = []
    for mode, m in result["modes"].items():
        for per, w in m.items():
            if not isinstance(w, dict) or "linux" not in w:
                continue
            lin, srv = w["linux"], w["servo"]
            k = f"{mode}_{per}"
            out += [
                {"name": f"{k}_missed_linux", "value": lin["missed"], "unit": "cycles", "better": "lower",
                 "note": f"of {lin['cycles'] + lin['missed']} in {w['guest_seconds']} s guest time"},
                {"name": f"{k}_missed_servo", "value": srv["missed"], "unit": "cycles", "better": "lower",
                 "note": f"of {srv['cycles'] + srv['missed']}"},
                {"name": f"{k}_servo_irq_latency_max", "unit": "us", "better": "lower",
                 "value": round(srv["irq_entry_latency_ns_max_since_start"] / 1000, 2),
                 "note": "TTC event -> servo handler, since start"},
                {"name": f"{k}_servod_wake_latency_max", "unit": "us", "better": "lower",
                 "value": round(lin["wake_latency_ns_since_start"]["max"] / 1000, 2),
                 "note": f"mean {lin['wake_latency_ns_since_start']['mean'] / 1000:.1f} us"},
                {"name": f"{k}_servo_handler_max", "unit": "us", "better": "lower",
                 "value": round(srv["cost_ticks_10ns_since_start"]["cycle"]["max"] / 100, 2),
                 "note": f"mean {srv['cost_ticks_10ns_since_start']['cycle']['mean'] / 100:.1f} us"},
            ]
            # per stage in instructions: under -icount shift=0 one instruction
            # is 1 ns of guest time, and the firmware counts in 10 ns ticks
            if mode == "virtual":
                cost = srv["cost_ticks_10ns_since_start"]
                for stage in ("rx", "ctrl", "tx", "cycle"):
                    out.append({"name": f"{k}_servo_{stage}_instructions", "unit": "instr",
                                "better": "lower", "value": cost[stage]["mean"] * 10,
                                "note": f"mean; max {cost[stage]['max'] * 10} since start"})
                axes = srv.get("axes") or 1
                out.append({"name": f"{k}_servo_ctrl_instructions_per_axis", "unit": "instr",
                            "better": "lower", "value": round(cost["ctrl"]["mean"] * 10 / axes),
                            "note": f"ctrl mean / {axes} axes (4 sub-steps each): an upper bound "
                                    "on the per-axis slope"})
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--short", type=float, default=3.0)
    ap.add_argument("--modes", default="virtual")
    ap.add_argument("--json", type=Path, default=REPO / "bench/results/cycle.json")
    args = ap.parse_args()
    board = qemu.Board.load("zynq7000_qemu")
    images = qemu.prepare_images(board)
    result: dict[str, object] = {
        **run_info(board, "cycle_bench.py"),
        "note": "QEMU TCG on a shared host: emulator figures, not Zynq-7000 hardware figures",
        "modes": {},
    }
    for mode in args.modes.split(","):
        if mode not in MODES:
            ap.error(f"--modes: {mode!r} is not one of {', '.join(MODES)}")
        clock, accel = MODES[mode]
        r = run_mode(board, images, clock, accel, args.seconds, args.short)
        result["modes"][mode] = {  # type: ignore[index]
            "clock": " ".join(qemu.clock_args(board, clock)) or "host",
            "accel": accel or "tcg (multi-threaded, default)", **r}
        for per, w in r.items():
            lin, srv = w["linux"], w["servo"]  # type: ignore[index]
            print(f"[{mode:11} {per:>6}] linux cycles {lin['cycles']} missed {lin['missed']} ({lin['miss_rate_pct']} %), "
                  f"servo cycles {srv['cycles']} missed {srv['missed']} ({srv['miss_rate_pct']} %), "
                  f"fb torn/invalid {lin['feedback']['torn']}/{lin['feedback']['invalid']}, "
                  f"cmd torn/invalid {srv['commands']['torn']}/{srv['commands']['invalid']}")
            cost = srv["cost_ticks_10ns_since_start"]
            print(f"                servo cost (10 ns ticks, mean/max): irq entry->commands consumed "
                  f"{cost['rx']['mean']}/{cost['rx']['max']}, control {cost['ctrl']['mean']}/{cost['ctrl']['max']}, "
                  f"feedback {cost['tx']['mean']}/{cost['tx']['max']}, whole {cost['cycle']['mean']}/{cost['cycle']['max']}")
            print(f"                servod: wake-up latency ns {lin['wake_latency_ns_since_start']}, "
                  f"work (wake->published) ns {lin['work_ns_wake_to_published']}")
            print(f"                servod wake-up histogram (window): {lin['wake_latency_histogram_window']}")
    result["figures"] = figures(result)
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(result, indent=2) + "\n")
    print(f"written {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
