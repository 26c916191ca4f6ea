#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""Figures of the cycle on the emulated board (QEMU), one boot per mode.

    .venv/bin/python bench/cycle/cycle_bench.py [--board zynq7000_qemu] [--seconds 10] [--short 3]
        [--modes virtual,host-single,host-multi] [--json bench/results/cycle.json]
        [--sweep-axes 1-8] [--sweep-rates 1000,2000,4000,8000] [--fit-rates 1000,4000]
        [--window-cycles 2000] [--long-cycles 100000] [--long-rate 4000] [--long-axes 8]

Modes: ``virtual`` (the default: -icount, guest time counts instructions,
single-threaded TCG; every figure is in guest ns, independent of host
load), ``host-single`` and ``host-multi`` (guest time on the host clock,
single- or multi-threaded TCG: figures depend on the host's load).

Boots --board (zynq7000_qemu by default; zynqmp_qemu: the servo on R5 0),
starts servod, then rpu_app through remoteproc (the instance servod
drives, found as servod finds it: netboard.FIND_RPROC), and runs the exchange for
--seconds at 1 ms and --short at 250 us (4 axes). Results go to
bench/results/cycle.json for zynq7000_qemu and cycle-<board>.json for any
other board (python/servoamp/bench.py, results_stem). Prints and stores,
per period: cycles and missed cycles on each side, exchange counters, the
per-cycle cost of the exchange on each side (servo: ticks of the
firmware's time base, BOARD_TIMEBASE_TICKS_PER_US from the board's servo
devicetree: the A9's global timer at 100 per us, the R5's PMU cycle
counter at 1000 per us; from the cycle handler's entry to commands
consumed / control / feedback published; Linux: wake-up to commands
published, CLOCK_MONOTONIC), the servo's interrupt entry latency and
servod's wake-up latency histogram (interrupt event to servod running,
read from its own TTC counter).

Then, in the same boot and in ``virtual`` mode only (issue 24, items 2
and 3):

- **the sweep**: for each axis count of --sweep-axes (``ampctl param set
  axes N``) and each rate of --sweep-rates (``cycle_period_us``), a window
  of --window-cycles cycles: missed cycles on both sides, the servo's cost
  per stage (the firmware starts its cost figures again at every change
  of the axis count or the period, so each point has its own) and Linux's
  work (wake-up to commands published: the window's exact mean from
  servod's ``linux.work_ns.sum``). From the points at each of --fit-rates
  a least-squares line over the axis count: instructions per axis (slope)
  and per cycle (intercept), servo and Linux. The rate table: per axis
  count, the highest rate with 0 missed on both sides at it and at every
  lower rate tried.
- **the long run**: --long-cycles cycles at --long-rate with --long-axes
  axes, 0 missed on both sides expected (issue 24: 100,000 at 4 kHz).

Under -icount shift=N (board.yaml qemu.clock.icount) one guest
instruction is 2^N ns of guest time, so a tick of the servo's time base is
1000 / ticks_per_us / 2^N instructions (TimeBase): on the A9 a 10 ns tick
is 10 instructions; on the R5, QEMU's PMCCNTR is the virtual clock in ns
(target/arm/helper.c cycles_get_count: QEMU_CLOCK_VIRTUAL at a fixed
ARM_CPU_FREQ of 1 GHz, the rate servo.dts gives), so a tick is one
instruction. Both cores share that one
instruction clock (single-threaded TCG runs them in turn): Linux's work in
ns counts CPU0's instructions as long as CPU1 sleeps in wfi meanwhile,
which it does in Linux's half of the cycle (docs/cycle-figures.md, "Figures").

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
from dataclasses import dataclass
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "python"))

from servoamp import netboard, qemu  # noqa: E402
from servoamp.bench import results_stem  # noqa: E402
from servoamp.images import RPU_APP_VARIANTS  # noqa: E402

GEN = REPO / "rpu_app" / "scripts"
BOOT_TIMEOUT_S = 300.0   # host seconds to the shell (the ZynqMP's TF-A boot: 1-2 min on a busy host)


@dataclass(frozen=True)
class TimeBase:
    """The servo's time base and the guest's instruction clock, from the
    board's data: ticks_per_us is BOARD_TIMEBASE_TICKS_PER_US as
    rpu_app's generator derives it from the servo devicetree, and
    ns_per_instruction is 2^shift of board.yaml's qemu.clock.icount."""
    ticks_per_us: int
    ns_per_instruction: int

    def instructions(self, ticks: float) -> float:
        return ticks * 1000 / self.ticks_per_us / self.ns_per_instruction

    def us(self, ticks: float) -> float:
        return ticks / self.ticks_per_us

    @classmethod
    def of(cls, board: qemu.Board) -> TimeBase:
        sys.path.insert(0, str(GEN))
        import gen_board_header as gen  # type: ignore[import-not-found]

        dts = board.folder / RPU_APP_VARIANTS[""]
        cfg, _, _ = gen.build(dts, [gen.DEFAULT_BINDINGS], board.name)
        icount = str(board.qemu["clock"]["icount"])
        shift = dict(kv.split("=", 1) for kv in icount.split(",") if "=" in kv).get("shift", "")
        if not shift.isdigit():
            raise ValueError(f"{board.name}: qemu.clock.icount {icount!r} has no fixed shift=N: "
                             "guest time is not a count of instructions")
        return cls(int(cfg["BOARD_TIMEBASE_TICKS_PER_US"]), 1 << int(shift))

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


def window(console: qemu.Uart, prompt: str, seconds: float, tb: TimeBase) -> dict[str, object]:
    a = stats(console, prompt)
    t0 = time.monotonic()
    qemu.run_shell(console, f"sleep {seconds}", prompt, timeout=seconds * 10 + 30)
    host = time.monotonic() - t0
    b = stats(console, prompt)
    d: dict[str, Any] = {}
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
            "ticks_per_us": tb.ticks_per_us,
            "cost_ticks_since_start": {
                p: {"mean": d[f"servo.{p}_ticks.mean"], "max": d[f"servo.{p}_ticks.max"]}
                for p in ("rx", "ctrl", "tx", "cycle")},
            "irq_entry_latency_ns_max_since_start": d["servo.irq_lat_ns.max"],
            "axes": d["servo.axes"],
        },
    }
    return res


SETTLE_S = 0.2     # after a change of axes or period, before a window opens


def point(console: qemu.Uart, prompt: str, axes: int, rate_hz: int, cycles: int, tb: TimeBase) -> dict[str, Any]:
    """One point of the sweep: axes and rate set, then a window of cycles.
    Counters are the window's (differences of two ``ampctl stats``); the
    servo's costs are since the change (the firmware starts them again
    when the axis count or the period changes); Linux's work is the
    window's exact mean (difference of servod's sums)."""
    period_us = round(1e6 / rate_hz)
    res: dict[str, Any] = {"axes": axes, "rate_hz": rate_hz, "period_us": period_us, "cycles_asked": cycles}
    rc, out = qemu.run_shell(console, f"ampctl param set axes {axes} 2>&1", prompt, timeout=30)
    if rc:
        raise RuntimeError(f"ampctl param set axes {axes} failed ({rc}):\n{out}")
    rc, out = qemu.run_shell(console, f"ampctl param set cycle_period_us {period_us} 2>&1", prompt, timeout=30)
    if rc:
        # the firmware refuses a period its worst measured handler cost
        # does not fit (SP_E_OVERLOAD, exit 6): a point not sustained
        res["refused"] = out.strip().splitlines()[-1] if out.strip() else f"exit {rc}"
        return res
    qemu.run_shell(console, f"sleep {SETTLE_S}", prompt, timeout=60)
    a = stats(console, prompt)
    seconds = (cycles + 2) / rate_hz
    qemu.run_shell(console, f"sleep {seconds:.4f}", prompt, timeout=seconds * 20 + 60)
    b = stats(console, prompt)

    def d(k: str) -> int:
        return int(b[k], 0) - int(a[k], 0)

    lin = d("linux.cycles")
    res.update({
        "linux": {"cycles": lin, "missed": d("linux.missed_irq"), "late": d("linux.late"),
                  "fb_torn": d("linux.fb_torn"), "fb_invalid": d("linux.fb_invalid"),
                  "fb_stale": d("linux.fb_stale"),
                  "work_ns_mean": round(d("linux.work_ns.sum") / max(1, lin), 1),
                  "wake_latency_histogram": {k.split(".", 2)[2]: d(k) for k in b
                                             if k.startswith("linux.wake_lat_hist.")}},
        "servo": {"cycles": d("servo.cycles"), "missed": d("servo.missed"),
                  "cmd_torn": d("servo.cmd_torn"), "cmd_invalid": d("servo.cmd_invalid"),
                  "cmd_stale": d("servo.cmd_stale"), "axes": int(b["servo.axes"], 0),
                  "period_us": int(b["servo.period_us"], 0),
                  "cost_samples": int(b["servo.cost_samples"], 0),
                  # instructions (TimeBase: ticks of the servo's time base), since the change
                  "instructions": {p: {"mean": round(tb.instructions(int(b[f"servo.{p}_ticks.mean"], 0))),
                                       "max": round(tb.instructions(int(b[f"servo.{p}_ticks.max"], 0)))}
                                   for p in ("rx", "ctrl", "tx", "cycle")},
                  "irq_entry_latency_ns_max": int(b["servo.irq_lat_ns.max"], 0)},
    })
    res["ok"] = res["linux"]["missed"] == 0 and res["servo"]["missed"] == 0
    return res


def fit(xs: list[float], ys: list[float]) -> dict[str, float]:
    """Least-squares line y = slope * x + intercept, and its largest residual."""
    n = len(xs)
    if n < 2:
        raise ValueError("a line needs two points")
    mx, my = sum(xs) / n, sum(ys) / n
    sxx = sum((x - mx) ** 2 for x in xs)
    slope = sum((x - mx) * (y - my) for x, y in zip(xs, ys)) / sxx
    icpt = my - slope * mx
    return {"slope": round(slope, 1), "intercept": round(icpt, 1),
            "max_residual": round(max(abs(y - (slope * x + icpt)) for x, y in zip(xs, ys)), 1), "points": n}


def fits(points: list[dict[str, Any]], rate_hz: int) -> dict[str, Any]:
    """Per axis, per cycle: the servo's stages (instructions) and Linux's
    work (ns: instructions, docstring) over the axis count at one rate."""
    pts = sorted((p for p in points if p["rate_hz"] == rate_hz and "servo" in p), key=lambda p: p["axes"])
    if len(pts) < 2:
        return {}
    xs = [float(p["axes"]) for p in pts]
    out: dict[str, Any] = {f"servo_{st}": fit(xs, [float(p["servo"]["instructions"][st]["mean"]) for p in pts])
                           for st in ("rx", "ctrl", "tx", "cycle")}
    out["servo_rx_tx"] = fit(xs, [float(p["servo"]["instructions"]["rx"]["mean"]
                                        + p["servo"]["instructions"]["tx"]["mean"]) for p in pts])
    out["linux_work_ns"] = fit(xs, [float(p["linux"]["work_ns_mean"]) for p in pts])
    out["axes"] = [p["axes"] for p in pts]
    return out


def rate_table(points: list[dict[str, Any]]) -> dict[str, Any]:
    """Per axis count: the highest rate sustained with 0 missed on both
    sides, at it and at every lower rate tried (0: not even the lowest)."""
    out: dict[str, Any] = {}
    for n in sorted({p["axes"] for p in points}):
        best = 0
        for p in sorted((p for p in points if p["axes"] == n), key=lambda p: p["rate_hz"]):
            if not p.get("ok"):
                break
            best = p["rate_hz"]
        out[str(n)] = best
    return out


def sweep(console: qemu.Uart, prompt: str, axes: list[int], rates: list[int], cycles: int,
          tb: TimeBase) -> list[dict[str, Any]]:
    pts = []
    for n in axes:
        for r in sorted(rates):
            p = point(console, prompt, n, r, cycles, tb)
            pts.append(p)
            if "refused" in p:
                print(f"[sweep {n} axes {r / 1000:g} kHz] refused: {p['refused']}", flush=True)
                continue
            lin, srv = p["linux"], p["servo"]
            ins = srv["instructions"]
            print(f"[sweep {n} axes {r / 1000:g} kHz] linux {lin['cycles']} cycles, missed {lin['missed']}, "
                  f"late {lin['late']}, work {lin['work_ns_mean']} ns; servo {srv['cycles']} cycles, missed "
                  f"{srv['missed']}; instructions mean rx {ins['rx']['mean']} ctrl {ins['ctrl']['mean']} "
                  f"tx {ins['tx']['mean']} cycle {ins['cycle']['mean']} (max {ins['cycle']['max']})", flush=True)
    return pts


def start_cycle(m: qemu.QemuMachine, prompt: str) -> qemu.Uart:
    """Boot to the shell, servod, the firmware through remoteproc, the
    exchange running (watchdog 50 cycles, as the suite has it)."""
    qemu.boot_to_shell(m, timeout=BOOT_TIMEOUT_S)
    c = m.uart(0)

    def sh(cmd: str) -> str:
        return qemu.run_shell(c, cmd, prompt, timeout=60.0)[1]

    sh("dmesg -n 1")
    sh("(servod > /tmp/servod.log 2>&1 &)")
    sh("while ! grep -q 'waiting for the servo' /tmp/servod.log; do sleep 0.05; done")
    rproc = netboard.find_rproc(sh)   # as servod finds it (netboard.FIND_RPROC)
    sh(f"echo rpu_app.elf > {rproc}/firmware; echo start > {rproc}/state")
    sh("while ! grep -q 'parameter set loaded' /tmp/servod.log; do sleep 0.05; done")
    sh("ampctl param set wd_limit 50; ampctl resume; true")
    return c


def run_mode(board: qemu.Board, images: qemu.Images, clock: str, accel: str | None, seconds: float,
             short: float, tb: TimeBase, sw: argparse.Namespace | None = None) -> dict[str, object]:
    """One boot: the 1 ms and 250 us windows (4 axes); with sw (virtual
    time only) the sweep and the long run after them."""
    prompt = str(board.data["linux"]["prompt"])
    m = qemu.QemuMachine(board, images, accel=accel, clock=clock)
    with m:
        c = start_cycle(m, prompt)

        def sh(cmd: str) -> None:
            qemu.run_shell(c, cmd, prompt, timeout=60.0)

        out: dict[str, object] = {}
        if seconds > 0:
            out["1000us"] = window(c, prompt, seconds, tb)
        if short > 0:
            sh("ampctl param set cycle_period_us 250; sleep 0.2")
            out["250us"] = window(c, prompt, short, tb)
            sh("ampctl param set cycle_period_us 1000")
        if sw is not None and sw.sweep_axes:
            t0 = time.monotonic()
            pts = sweep(c, prompt, sw.sweep_axes, sw.sweep_rates, sw.window_cycles, tb)
            out["sweep"] = {"window_cycles": sw.window_cycles, "settle_s": SETTLE_S,
                            "host_seconds": round(time.monotonic() - t0, 1), "points": pts,
                            "fits": {f"{r}hz": fits(pts, r) for r in sw.fit_rates},
                            "max_rate_hz": rate_table(pts)}
        if sw is not None and sw.long_cycles:
            t0 = time.monotonic()
            p = point(c, prompt, sw.long_axes, sw.long_rate, sw.long_cycles, tb)
            p["host_seconds"] = round(time.monotonic() - t0, 1)
            out["long"] = p
        sh("ampctl param set axes 4; ampctl param set cycle_period_us 1000")
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
    ns_per_instr = int(result.get("timebase", {}).get("ns_per_instruction", 1))
    for mode, m in result["modes"].items():
        out += sweep_figures(m)
        for per, w in m.items():
            if not isinstance(w, dict) or "linux" not in w or per == "long":
                continue
            lin, srv = w["linux"], w["servo"]
            # results from before --board carry A9 ticks of 10 ns under their own key
            tb = TimeBase(int(srv.get("ticks_per_us", 100)), ns_per_instr)
            cost = srv.get("cost_ticks_since_start") or srv["cost_ticks_10ns_since_start"]
            k = f"{mode}_{per}"
            out += [
                {"name": f"{k}_missed_linux", "value": lin["missed"], "unit": "cycles", "better": "lower",
                 "note": f"of {lin['cycles'] + lin['missed']} in {w['guest_seconds']} s guest time"},
                {"name": f"{k}_missed_servo", "value": srv["missed"], "unit": "cycles", "better": "lower",
                 "note": f"of {srv['cycles'] + srv['missed']}"},
                {"name": f"{k}_servo_irq_latency_max", "unit": "us", "better": "lower",
                 "value": round(srv["irq_entry_latency_ns_max_since_start"] / 1000, 2),
                 "note": "TTC event -> servo handler, max since the start or the last change of axes or period"},
                {"name": f"{k}_servod_wake_latency_max", "unit": "us", "better": "lower",
                 "value": round(lin["wake_latency_ns_since_start"]["max"] / 1000, 2),
                 "note": f"mean {lin['wake_latency_ns_since_start']['mean'] / 1000:.1f} us"},
                {"name": f"{k}_servo_handler_max", "unit": "us", "better": "lower",
                 "value": round(tb.us(cost["cycle"]["max"]), 2),
                 "note": f"mean {tb.us(cost['cycle']['mean']):.1f} us"},
            ]
            # per stage in instructions (TimeBase: -icount makes guest time a
            # count of instructions; the firmware counts ticks of its time base)
            if mode == "virtual":
                for stage in ("rx", "ctrl", "tx", "cycle"):
                    out.append({"name": f"{k}_servo_{stage}_instructions", "unit": "instr",
                                "better": "lower", "value": round(tb.instructions(cost[stage]["mean"])),
                                "note": f"mean; max {round(tb.instructions(cost[stage]['max']))} since the start "
                                        "or the last change of axes or period"})
                axes = srv.get("axes") or 1
                out.append({"name": f"{k}_servo_ctrl_instructions_per_axis", "unit": "instr",
                            "better": "lower", "value": round(tb.instructions(cost["ctrl"]["mean"]) / axes),
                            "note": f"ctrl mean / {axes} axes (4 sub-steps each): an upper bound "
                                    "on the per-axis slope"})
    return out


def sweep_figures(m: dict[str, Any]) -> list[dict[str, Any]]:
    """The sweep's and the long run's figures (issue 24, items 2 and 3)."""
    out: list[dict[str, Any]] = []
    sw = m.get("sweep")
    if sw:
        for key, f in sw["fits"].items():
            if not f:
                continue
            k = f"fit_{int(key[:-2]) / 1000:g}khz"
            ax = f"axes {f['axes'][0]}..{f['axes'][-1]}, {len(f['axes'])} windows of {sw['window_cycles']} cycles"
            for st, what in (("cycle", "the whole handler"), ("ctrl", "control, 4 sub-steps")):
                out.append({"name": f"{k}_servo_{st}_instructions_per_axis", "unit": "instr", "better": "lower",
                            "value": f[f"servo_{st}"]["slope"],
                            "note": f"{what}: least-squares slope over {ax}; intercept "
                                    f"{f[f'servo_{st}']['intercept']:g}, max residual {f[f'servo_{st}']['max_residual']:g}"})
            out.append({"name": f"{k}_servo_cycle_instructions_intercept", "unit": "instr", "better": "lower",
                        "value": f["servo_cycle"]["intercept"], "note": "the whole handler, per cycle, at 0 axes (fit)"})
            rxtx = f["servo_rx_tx"]
            out.append({"name": f"{k}_servo_rx_tx_instructions_per_axis", "unit": "instr", "better": "lower",
                        "value": rxtx["slope"], "note": f"amp_lib rx + tx: intercept {rxtx['intercept']:g}"})
            lw = f["linux_work_ns"]
            out.append({"name": f"{k}_linux_work_ns_per_axis", "unit": "ns", "better": "lower",
                        "value": lw["slope"], "note": f"servod wake-up -> commands published, slope over {ax}; "
                                                      f"max residual {lw['max_residual']:g}"})
            out.append({"name": f"{k}_linux_work_ns_intercept", "unit": "ns", "better": "lower",
                        "value": lw["intercept"], "note": "servod wake-up -> commands published, at 0 axes (fit)"})
        most = max(p["axes"] for p in sw["points"])
        for p in sw["points"]:
            if p["axes"] != most or "servo" not in p or p["rate_hz"] not in (1000, 4000):
                continue
            k = f"sweep_{p['rate_hz'] / 1000:g}khz_{most}axes"
            ins = p["servo"]["instructions"]
            out.append({"name": f"{k}_servo_rx_tx_instructions", "unit": "instr", "better": "lower",
                        "value": ins["rx"]["mean"] + ins["tx"]["mean"],
                        "note": f"amp_lib on the servo: entry -> commands consumed {ins['rx']['mean']} + "
                                f"feedback published {ins['tx']['mean']}, means"})
            out.append({"name": f"{k}_servo_rx_instructions", "unit": "instr", "better": "lower",
                        "value": ins["rx"]["mean"],
                        "note": f"cycle handler entry -> commands consumed, mean; max {ins['rx']['max']}"})
        for n, r in sw["max_rate_hz"].items():
            tried = sorted(p["rate_hz"] for p in sw["points"] if p["axes"] == int(n))
            bad = [f"{p['rate_hz'] / 1000:g} kHz: " + (p["refused"] if "refused" in p else
                   f"missed {p['linux']['missed']}/{p['servo']['missed']}")
                   for p in sw["points"] if p["axes"] == int(n) and not p.get("ok")]
            out.append({"name": f"max_rate_khz_{n}axes", "unit": "kHz", "better": "higher", "value": r / 1000,
                        "note": f"0 missed both sides in {sw['window_cycles']} cycles; tried "
                                f"{', '.join(f'{t / 1000:g}' for t in tried)} kHz"
                                + (f"; {'; '.join(bad)}" if bad else "")})
    lg = m.get("long")
    if lg:
        k = f"long_{lg['rate_hz'] / 1000:g}khz_{lg['axes']}axes"
        if "refused" in lg:
            out.append({"name": f"{k}_refused", "unit": "runs", "better": "lower", "value": 1, "note": lg["refused"]})
        else:
            out += [
                {"name": f"{k}_missed_linux", "value": lg["linux"]["missed"], "unit": "cycles", "better": "lower",
                 "note": f"of {lg['linux']['cycles'] + lg['linux']['missed']} ({lg['cycles_asked']} asked); "
                         f"late {lg['linux']['late']}"},
                {"name": f"{k}_missed_servo", "value": lg["servo"]["missed"], "unit": "cycles", "better": "lower",
                 "note": f"of {lg['servo']['cycles'] + lg['servo']['missed']}"},
                {"name": f"{k}_cycles", "value": min(lg["linux"]["cycles"], lg["servo"]["cycles"]),
                 "unit": "cycles", "better": "higher",
                 "note": f"cycles run on both sides (the lower of the two) with {lg['axes']} axes"},
            ]
    return out


def print_sweep(r: dict[str, Any]) -> None:
    """The fits, the rate table and the long run, as text."""
    sw = r.get("sweep")
    if sw:
        for key, f in sw["fits"].items():
            if not f:
                continue
            print(f"per axis at {int(key[:-2]) / 1000:g} kHz (least squares over axes {f['axes']}):")
            for name, unit in (("servo_rx", "instr"), ("servo_ctrl", "instr"), ("servo_tx", "instr"),
                               ("servo_cycle", "instr"), ("servo_rx_tx", "instr"), ("linux_work_ns", "ns")):
                v = f[name]
                print(f"    {name:14} {v['slope']:8.1f} {unit}/axis + {v['intercept']:8.1f} {unit} "
                      f"(max residual {v['max_residual']:g})")
        rates = sorted({p["rate_hz"] for p in sw["points"]})
        print("highest rate with 0 missed (both sides), per axis count; missed linux/servo per rate:")
        print("    axes  " + "  ".join(f"{x / 1000:>9g} kHz" for x in rates) + "   highest")
        for n, best in sw["max_rate_hz"].items():
            cells = []
            for x in rates:
                p = next((p for p in sw["points"] if p["axes"] == int(n) and p["rate_hz"] == x), None)
                cells.append("-" if p is None else "refused" if "refused" in p
                             else f"{p['linux']['missed']}/{p['servo']['missed']}")
            print(f"    {n:>4}  " + "  ".join(f"{c:>13}" for c in cells) + f"   {best / 1000:g} kHz")
    lg = r.get("long")
    if lg:
        if "refused" in lg:
            print(f"long run: {lg['rate_hz']} Hz refused: {lg['refused']}")
        else:
            print(f"long run: {lg['axes']} axes at {lg['rate_hz'] / 1000:g} kHz, {lg['cycles_asked']} cycles asked: "
                  f"linux {lg['linux']['cycles']} cycles, missed {lg['linux']['missed']}, late {lg['linux']['late']}; "
                  f"servo {lg['servo']['cycles']} cycles, missed {lg['servo']['missed']}; "
                  f"{lg['host_seconds']} s of host time")


def axes_list(text: str) -> list[int]:
    """'1-8' or '1,4,8' (or '' for none) -> [1, ..., 8], each within 1..8."""
    out: list[int] = []
    for part in filter(None, text.split(",")):
        lo, _, hi = part.partition("-")
        out += list(range(int(lo), int(hi or lo) + 1))
    if any(not 1 <= n <= 8 for n in out):
        raise argparse.ArgumentTypeError(f"axes {text!r}: each within 1..8 (AMP_MAX_AXES)")
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--short", type=float, default=3.0)
    ap.add_argument("--modes", default="virtual")
    ap.add_argument("--board", default="zynq7000_qemu", help="the board folder under boards/ (default zynq7000_qemu)")
    ap.add_argument("--json", type=Path, help="results file (default bench/results/cycle.json for zynq7000_qemu, "
                                              "cycle-<board>.json for another board)")
    ap.add_argument("--sweep-axes", type=axes_list, default=list(range(1, 9)),
                    help="axis counts of the sweep ('1-8', '1,4,8', '' for no sweep)")
    ap.add_argument("--sweep-rates", type=lambda t: [int(x) for x in t.split(",")], default=[1000, 2000, 4000, 8000],
                    help="cycle rates in Hz (periods 125..10000 us)")
    ap.add_argument("--fit-rates", type=lambda t: [int(x) for x in t.split(",")], default=[1000, 4000],
                    help="rates whose points give the per-axis fits")
    ap.add_argument("--window-cycles", type=int, default=2000, help="cycles per sweep window")
    ap.add_argument("--long-cycles", type=int, default=100_000, help="cycles of the long run (0: none)")
    ap.add_argument("--long-rate", type=int, default=4000, help="Hz")
    ap.add_argument("--long-axes", type=int, default=8, choices=range(1, 9))
    args = ap.parse_args()
    for r in args.sweep_rates + [args.long_rate]:
        if not 100 <= r <= 8000:
            ap.error(f"rate {r} Hz: the period must be within 125..10000 us")
    if not (REPO / "boards" / args.board / "board.yaml").exists():
        ap.error(f"--board {args.board}: no boards/{args.board}/board.yaml")
    board = qemu.Board.load(args.board)
    if args.json is None:
        args.json = REPO / "bench" / "results" / f"{results_stem('cycle', board.name)}.json"
    tb = TimeBase.of(board)
    images = qemu.prepare_images(board)
    result: dict[str, object] = {
        **run_info(board, "cycle_bench.py"),
        "board": board.name,
        "timebase": {"ticks_per_us": tb.ticks_per_us, "ns_per_instruction": tb.ns_per_instruction,
                     "source": f"BOARD_TIMEBASE_TICKS_PER_US of boards/{board.name}/{RPU_APP_VARIANTS['']}; "
                               f"qemu.clock.icount of boards/{board.name}/board.yaml"},
        "note": f"QEMU TCG on a shared host: emulator figures, not {board.name} hardware figures "
                "(no caches or pipeline modelled: one instruction per ns of guest time)",
        "modes": {},
    }
    for mode in args.modes.split(","):
        if mode not in MODES:
            ap.error(f"--modes: {mode!r} is not one of {', '.join(MODES)}")
        clock, accel = MODES[mode]
        r = run_mode(board, images, clock, accel, args.seconds, args.short, tb, args if mode == "virtual" else None)
        result["modes"][mode] = {  # type: ignore[index]
            "clock": " ".join(qemu.clock_args(board, clock)) or "host",
            "accel": accel or "tcg (multi-threaded, default)", **r}
        for per, w in r.items():
            if per in ("sweep", "long"):
                continue
            lin, srv = w["linux"], w["servo"]  # type: ignore[index]
            print(f"[{mode:11} {per:>6}] linux cycles {lin['cycles']} missed {lin['missed']} ({lin['miss_rate_pct']} %), "
                  f"servo cycles {srv['cycles']} missed {srv['missed']} ({srv['miss_rate_pct']} %), "
                  f"fb torn/invalid {lin['feedback']['torn']}/{lin['feedback']['invalid']}, "
                  f"cmd torn/invalid {srv['commands']['torn']}/{srv['commands']['invalid']}")
            cost = srv["cost_ticks_since_start"]
            print(f"                servo cost ({tb.ticks_per_us} ticks per us, mean/max): irq entry->commands consumed "
                  f"{cost['rx']['mean']}/{cost['rx']['max']}, control {cost['ctrl']['mean']}/{cost['ctrl']['max']}, "
                  f"feedback {cost['tx']['mean']}/{cost['tx']['max']}, whole {cost['cycle']['mean']}/{cost['cycle']['max']}")
            print(f"                servod: wake-up latency ns {lin['wake_latency_ns_since_start']}, "
                  f"work (wake->published) ns {lin['work_ns_wake_to_published']}")
            print(f"                servod wake-up histogram (window): {lin['wake_latency_histogram_window']}")
        print_sweep(r)
    result["figures"] = figures(result)
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(result, indent=2) + "\n")
    print(f"written {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
