#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""CAN bus load per cycle and the highest axes x rate per bus with no SYNC
missed (issue 22): the servo firmware as CANopen master in QEMU (without
Linux, as tests/rpu_app/test_rpu_can_qemu.py runs it), its buses linked in
lockstep to the drive simulator (docs/canlink.md, docs/fieldbus.md).

    .venv/bin/python bench/fieldbus/can_bench.py [--cycles 2000]
        [--rates 1000,2000,4000] [--drives 1-4] [--json bench/results/fieldbus.json]

For each cycle rate, the firmware is built from a devicetree overlay of
boards/zynq7000_qemu/servo.dts (cycle-period-us, the axes on CAN drives)
in build/bench/fieldbus/; one QEMU boot measures two points, one per bus
(CAN0 with n drives, CAN1 with m). A point the firmware's build refuses
(gen_board_header.py: the worst-case SYNC + RPDO + TPDO bits of a cycle
over the bus time of a period) is reported as refused, not run.

Per point, after every drive is in "operation enabled" (app_debug.
force_enable through the gdbstub), a window of --cycles cycles:
  - from the firmware's `stats can=N` lines: SYNCs sent, SYNCs missed
    (TX FIFO full), PDOs missing;
  - from a canlink client on the bus (guest time, every frame the guest
    sent and every answer; it only sends DONEs, see tap()): bits per cycle = the sum of
    servoamp.canlink.frame_bits() of the frames between two SYNCs; load =
    bits x bit time / period. Compared with the firmware's compile-time
    estimate (BOARD_CANn_LOAD_PERMILLE) and the analytic figure (SYNC +
    n x (RPDO + TPDO) of 6 bytes, without stuff bits).

Guest time is virtual (-icount): the figures do not depend on the host.
"""
from __future__ import annotations

import argparse
import importlib
import json
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "python"))
sys.path.insert(0, str(REPO / "tests" / "rpu_app"))

from servoamp import canlink, canload  # noqa: E402

BOARD = "zynq7000_qemu"
BASE_DTS = REPO / "boards" / BOARD / "servo.dts"
BITRATE = 1_000_000
SYNC_ID = 0x080
STATS_CYCLES = 1000     # servo.dts stats-cycles: one statistics line per bus every 1000 cycles
# CANopen function codes (COB-ID & 0x780) of the frames on the bus
KINDS = {0x000: "nmt", 0x080: "emcy", 0x180: "tpdo1", 0x200: "rpdo1", 0x580: "sdo", 0x600: "sdo",
         0x700: "heartbeat"}
CYCLE_RE = re.compile(r"^stats cycle=(\d+) guest_us=(\d+) .*missed=(\d+)", re.M)


def bits_unstuffed(dlc: int) -> int:
    """Bits of a standard data frame without stuff bits (SOF..EOF + IFS)."""
    return 34 + 8 * dlc + canlink.TRAILER_BITS


def bits_worst(dlc: int) -> int:
    """gen_board_header.py's worst case (every possible stuff bit)."""
    unstuffed = 34 + 8 * dlc
    return unstuffed + (unstuffed - 1) // 4 + 13


def analytic_bits(n: int) -> tuple[int, int]:
    """(nominal, worst case) bits of one cycle with n drives: nominal is
    SYNC + n x (RPDO1 + TPDO1, both 6 bytes) without stuffing; the worst
    case, gen_board_header.py's check, adds each drive's heartbeat (1 byte:
    all may fall in one cycle) and every possible stuff bit."""
    return (bits_unstuffed(0) + 2 * n * bits_unstuffed(6),
            bits_worst(0) + n * (2 * bits_worst(6) + bits_worst(1)))


# ---- builds -----------------------------------------------------------------

def overlay(period_us: int, drives: dict[int, int]) -> str:
    """servo.dts with ``drives[bus]`` CAN axes on each bus (node ids 1..n),
    the remaining of axes 0..3 on the model, and ``period_us``; the
    master's time stamp off (it costs one 4-byte frame in its cycles, which
    the build's check counts: the maximum is measured without it)."""
    lines = [f'/include/ "{BASE_DTS}"', "", "&servo {", f"\tcycle-period-us = <{period_us}>;",
             "\tcan-time-stamp-ms = <0>;", "};", ""]
    idx = 0
    extra = []
    for bus in sorted(drives):
        for node in range(1, drives[bus] + 1):
            body = (f'\tservoamp,backend = "can";\n\tservoamp,can-bus = <{bus}>;\n'
                    f"\tservoamp,node-id = <{node}>;\n")
            if idx < 4:
                lines += [f"&axis{idx} {{", body.rstrip("\n"), "};", ""]
            else:
                extra.append(f"\taxis@{idx} {{\n\t\tcompatible = \"servoamp,servo-axis\";\n\t\treg = <{idx}>;\n"
                             + body.replace("\t", "\t\t") + "\t};\n")
            idx += 1
    if extra:
        lines += ["&servo {", *extra, "};", ""]
    return "\n".join(lines)


@dataclass
class Build:
    period_us: int
    drives: dict[int, int]
    dir: Path
    ok: bool = False
    why: str = ""
    load_permille: dict[int, int] = field(default_factory=dict)

    @property
    def mask(self) -> int:
        return (1 << sum(self.drives.values())) - 1


def build(period_us: int, drives: dict[int, int], root: Path, jobs: int) -> Build:
    name = f"p{period_us}-" + "-".join(f"can{b}x{n}" for b, n in sorted(drives.items()))
    d = root / name
    d.mkdir(parents=True, exist_ok=True)
    dts = d / "servo-bench.dts"
    text = overlay(period_us, drives)
    if not dts.exists() or dts.read_text() != text:
        dts.write_text(text)
    out = d / BOARD
    r = subprocess.run(["make", "-C", str(REPO / "rpu_app"), f"-j{jobs}", f"BOARD={BOARD}", f"BUILD={out}",
                        f"DTS={dts}", f"PYTHON={sys.executable}"], capture_output=True, text=True)
    b = Build(period_us, drives, out)
    if r.returncode:
        m = re.search(r"bus \d+: \d+ axes need up to \d+ bit times per cycle, \d+ available[^\n]*", r.stderr + r.stdout)
        if not m:
            raise RuntimeError(f"make for {dts} failed:\n{r.stdout[-2000:]}\n{r.stderr[-2000:]}")
        b.why = m.group(0)
        return b
    b.ok = True
    hdr = (out / "board_config.h").read_text()
    for m2 in re.finditer(r"^#define BOARD_CAN(\d)_LOAD_PERMILLE BOARD_U\((\d+)\)", hdr, re.M):
        b.load_permille[int(m2.group(1))] = int(m2.group(2))
    return b


# ---- one run ----------------------------------------------------------------

def tap(path: Path, out: Path) -> int:
    """The bench's canlink client, in a process of its own (--tap): every
    record QEMU sends, raw, into ``out`` until BYE.

    It says ACTIVE and answers every guest frame with a bare DONE: QEMU
    then waits for it (guest time stands still meanwhile, so the figures do
    not change) instead of dropping it when its socket fills, as it drops a
    passive client that falls behind (seen on the shared host, with the
    client as a thread of the bench and as a process of its own). It sends
    no frame: the bus is the same (the figures equal a passive run's)."""
    deadline = time.monotonic() + 120
    while not path.exists():
        if time.monotonic() > deadline:
            print(f"tap: {path} never appeared", file=sys.stderr)
            return 1
        time.sleep(0.02)
    link = canlink.Link.connect(str(path), active=True, name="bench", timeout=60)
    with open(out, "wb", buffering=1 << 16) as f:
        try:
            while True:
                rec = link.recv(None)
                if rec is None or rec.type == canlink.BYE:
                    return 0
                f.write(canlink.pack(rec))
                if not rec.info:
                    link.done(rec.seq)
        except (canlink.ProtocolError, OSError) as e:
            print(f"tap: {e}", file=sys.stderr)
            return 0 if link.closed else 1


def tap_frames(raw: Path) -> list[tuple[int, int, int]]:
    """(end time ns, COB-ID, bits) of every frame a tap saved."""
    data = raw.read_bytes() if raw.exists() else b""
    out = []
    for k in range(0, len(data) - len(data) % canlink.RECORD_SIZE, canlink.RECORD_SIZE):
        rec = canlink.unpack(data[k:k + canlink.RECORD_SIZE])
        if rec.type == canlink.FRAME:
            out.append((rec.t_ns, rec.can_id, canlink.frame_bits(rec.can_id, rec.eff, rec.rtr, rec.dlc, rec.data)))
    return out


def wait_uart(q: Any, pattern: str, count: int = 1, timeout: float = 60.0) -> None:
    """QemuRpu.wait_uart, rescanning UART1's text every 0.1 s instead of
    every 0.02 s (less CPU taken from the lockstep run on a shared host)."""
    rx = re.compile(pattern, re.M)
    deadline = time.monotonic() + timeout
    while len(rx.findall(q.uart_text())) < count:
        if not q.machine.running:
            raise RuntimeError(f"QEMU exited; UART1:\n{q.uart_text()[-3000:]}")
        if time.monotonic() > deadline:
            raise TimeoutError(f"{pattern!r} x{count} not on UART1 after {timeout} s:\n{q.uart_text()[-3000:]}")
        time.sleep(0.1)


def bus_load(frames: list[tuple[int, int, int]], t0_ns: int, t1_ns: int, period_us: int) -> dict[str, Any]:
    """Bits per cycle from SYNC to SYNC (guest frames and answers by their
    end on the bus) within [t0, t1]."""
    syncs = [t for t, cid, _ in frames if cid == SYNC_ID and t0_ns <= t <= t1_ns]
    if len(syncs) < 3:
        return {"error": f"{len(syncs)} SYNCs seen in the window"}
    per: list[int] = []
    j = 0
    fr = sorted(f for f in frames if syncs[0] < f[0] <= syncs[-1])
    for k in range(1, len(syncs)):
        s = 0
        while j < len(fr) and fr[j][0] <= syncs[k]:
            s += fr[j][2]
            j += 1
        per.append(s)
    kinds: dict[str, int] = {}
    for _, cid, bits in fr:
        kind = KINDS.get(cid & 0x780, "other") if cid != SYNC_ID else "sync"
        kinds[kind] = kinds.get(kind, 0) + bits
    per.sort()
    mean = sum(per) / len(per)
    gaps = [b - a for a, b in zip(syncs, syncs[1:])]
    bit_ns = 1e9 / BITRATE
    return {
        "cycles": len(per), "bits_mean": round(mean, 1), "bits_min": per[0],
        "bits_p50": per[len(per) // 2], "bits_max": per[-1],
        "load_mean_pct": round(100 * mean * bit_ns / (period_us * 1000), 2),
        "load_max_pct": round(100 * per[-1] * bit_ns / (period_us * 1000), 2),
        "sync_gap_ns": {"min": min(gaps), "max": max(gaps), "mean": round(sum(gaps) / len(gaps))},
        "bits_per_cycle_by_kind": {k: round(v / len(per), 1) for k, v in sorted(kinds.items())},
        "ids": sorted({f"{cid:#05x}" for _, cid, _ in fr}),
    }


def run_boot(b: Build, cycles: int, workdir: Path, log: Any) -> dict[int, dict[str, Any]]:
    qr: Any = importlib.import_module("qemu_rpu")  # tests/rpu_app (untyped)
    QemuRpu, _symbol = qr.QemuRpu, qr._symbol

    sockdir = Path(tempfile.mkdtemp(prefix="canbench-"))
    sims: list[subprocess.Popen[bytes]] = []
    taps: dict[int, subprocess.Popen[bytes]] = {}
    out: dict[int, dict[str, Any]] = {}
    try:
        links: dict[int, Path] = {}
        for bus, n in sorted(b.drives.items()):
            links[bus] = sockdir / f"can{bus}.sock"
            slog = open(workdir / f"drivesim{bus}.log", "w")
            sims.append(subprocess.Popen([sys.executable, "-m", "servoamp.drivesim", "--socket", str(links[bus]),
                                          "--nodes", f"1-{n}", "--wait", "120", "-v"], stdout=slog,
                                         stderr=subprocess.STDOUT, cwd=REPO))
            taps[bus] = subprocess.Popen([sys.executable, __file__, "--tap", str(links[bus]), "--json",
                                          str(workdir / f"can{bus}.rec")], stderr=open(workdir / f"tap{bus}.log", "w"))
        elf = b.dir / "servo.elf"
        t_host = time.monotonic()
        with QemuRpu(workdir / "q", b.dir / "qemu-stub.elf", elf, can_links=links,
                     can_link_opts={"timeout-ms": 2000}) as q:
            wait_uart(q, r"^running:", timeout=60)
            g = q.attach_gdb()
            g.interrupt()
            g.select_cpu(0)
            g.write32(_symbol(elf, "app_debug"), b.mask)
            g.cont()
            n_axes = sum(b.drives.values())
            wait_uart(q, r"^axis\d+: can\d node \d+: operation enabled, error 0000", count=n_axes, timeout=300)
            last_bus = max(b.drives)
            last = rf"^stats canps={last_bus} "
            n0 = len(re.findall(last, q.uart_text(), re.M))
            intervals = max(1, round(cycles / STATS_CYCLES))
            # one full interval to settle, then the window
            wait_uart(q, last, count=n0 + 1 + intervals, timeout=60 + cycles * b.period_us / 1e6 * 60)
            text = q.uart_text()
            host_s = time.monotonic() - t_host
        log.write(text)
        cyc = [tuple(map(int, m.groups())) for m in CYCLE_RE.finditer(text)]
        c0, c1 = cyc[n0], cyc[n0 + intervals]
        t0_ns, t1_ns = c0[1] * 1000, c1[1] * 1000
        for bus, n in sorted(b.drives.items()):
            st = canload.master_stats(text, bus)
            a, z = st[n0], st[n0 + intervals]
            d = {k: z[k] - a[k] for k in ("sync", "sync_missed", "rpdo", "rpdo_missed", "tpdo", "pdo_missing",
                                         "emcy", "hb_timeouts", "faults", "rx_bad")}
            try:
                taps[bus].wait(timeout=30)  # QEMU has quit: BYE
            except subprocess.TimeoutExpired:
                taps[bus].kill()
            frames = tap_frames(workdir / f"can{bus}.rec")
            tap_err = (workdir / f"tap{bus}.log").read_text().strip()
            load = bus_load(frames, t0_ns, t1_ns, b.period_us)
            with open(workdir / f"can{bus}-frames.txt", "w") as ff:  # the window: end time ns, id, bits
                ff.writelines(f"{t} {cid:03x} {bits}\n" for t, cid, bits in frames if t0_ns <= t <= t1_ns)
            nominal, worst = analytic_bits(n)
            out[bus] = {
                "drives": n, "period_us": b.period_us, "rate_hz": round(1e6 / b.period_us),
                "window": {"cycles": c1[0] - c0[0], "guest_us": c1[1] - c0[1], "servo_missed": c1[2] - c0[2],
                           "host_s_whole_boot": round(host_s, 1)},
                "stats": d, "nodes_op": z["nodes_op"],
                "bus": load, "tap_error": tap_err,
                "analytic_bits": {"nominal_unstuffed": nominal, "worst_case": worst},
                "analytic_load_pct": {"nominal_unstuffed": round(100 * nominal / b.period_us, 2),
                                      "worst_case": round(100 * worst / b.period_us, 2)},
                "firmware_load_permille": b.load_permille.get(bus),
                "pass": d["sync_missed"] == 0 and z["nodes_op"] == n and d["sync"] > 0,
            }
    finally:
        for s in sims + list(taps.values()):
            s.terminate()
            try:
                s.wait(timeout=10)
            except subprocess.TimeoutExpired:
                s.kill()
        shutil.rmtree(sockdir, ignore_errors=True)
    return out


# ---- the sweep ----------------------------------------------------------------

AXES_IN_USE = 4   # the firmware cycles the first "axes" (parameter, default 4) axes; the rest stay disabled


def boots_for(drives: list[int]) -> list[dict[int, int]]:
    """Two points per boot where they fit: CAN0 and CAN1, at most
    AXES_IN_USE drives in all (without Linux nobody raises "axes")."""
    ds = sorted(drives)
    boots = []
    while ds:
        a = ds.pop(-1)
        b = next((x for x in ds if a + x <= AXES_IN_USE), None)
        if b is not None:
            ds.remove(b)
        boots.append({0: a} if b is None else {0: a, 1: b})
    return sorted(boots, key=lambda c: sorted(c.values()))


def parse_range(s: str) -> list[int]:
    out: list[int] = []
    for part in s.split(","):
        if "-" in part:
            lo, hi = part.split("-")
            out += range(int(lo), int(hi) + 1)
        else:
            out.append(int(part))
    return out


def sync_jitter(p: dict[str, Any]) -> tuple[float, str] | None:
    """A point's SYNC jitter (us: the farthest SYNC-to-SYNC spacing from the
    period) and its range, if measured."""
    g = p.get("bus", {}).get("sync_gap_ns")
    if g is None:
        return None
    per = p["period_us"] * 1000
    return (round(max(per - g["min"], g["max"] - per) / 1000, 1),
            f"{g['min'] / 1000:.1f}..{g['max'] / 1000:.1f} us")


def tag_of(p: dict[str, Any]) -> str:
    return f"{p['drives']}drives_{p['rate_hz'] // 1000}khz"


def figures(points: list[dict[str, Any]], rates: list[int],
            baseline: dict[str, Any] | None = None) -> list[dict[str, Any]]:
    """The figures; with ``baseline`` (another QEMU measured in the same
    run), each SYNC jitter's note gives its figure there too."""
    f: list[dict[str, Any]] = []
    for p in points:
        if p.get("refused"):
            continue
        tag = tag_of(p)
        bus = p["bus"]
        if "bits_mean" in bus:
            f.append({"name": f"load_pct_{tag}", "value": bus["load_mean_pct"], "unit": "%", "better": "lower",
                      "note": f"{bus['bits_mean']:.0f} bits/cycle mean, max {bus['bits_max']} ({bus['load_max_pct']} %); "
                              f"firmware estimate {p['firmware_load_permille'] / 10:.1f} %, analytic "
                              f"{p['analytic_load_pct']['nominal_unstuffed']} % unstuffed"})
            f.append({"name": f"load_max_pct_{tag}", "value": bus["load_max_pct"], "unit": "%", "better": "lower",
                      "note": f"the busiest cycle of {bus['cycles']}: {bus['bits_max']} bits (the drives' heartbeats "
                              "in one cycle)"})
        jit = sync_jitter(p)
        if jit is not None:
            note = f"SYNC to SYNC on the bus {jit[1]} (the end of the SYNC frame, guest time)"
            before = baseline["sync_jitter"].get(tag) if baseline is not None else None
            if baseline is not None and before is not None:
                note += f"; {before[0]} us ({before[1]}) with {baseline['label']}, in the same run"
            f.append({"name": f"sync_jitter_us_{tag}", "unit": "us", "better": "lower", "value": jit[0],
                      "note": note})
        f.append({"name": f"sync_missed_{tag}", "value": p["stats"]["sync_missed"], "unit": "cycles",
                  "better": "lower", "note": f"of {p['stats']['sync']} SYNCs; pdo_missing {p['stats']['pdo_missing']}"})
    for r in rates:
        ok = [p["drives"] for p in points if p["rate_hz"] == r and p.get("pass")]
        f.append({"name": f"max_drives_per_bus_{r // 1000}khz", "value": max(ok, default=0), "unit": "drives",
                  "better": "higher", "note": "most drives on one bus with 0 SYNC missed (points the build refuses count as failed)"})
        ok2 = [p["drives"] for p in points if p["rate_hz"] == r and p.get("pass") and p["stats"]["pdo_missing"] == 0]
        f.append({"name": f"max_drives_per_bus_{r // 1000}khz_no_pdo_missing", "value": max(ok2, default=0),
                  "unit": "drives", "better": "higher",
                  "note": "the same, and every TPDO of every cycle received before the next cycle"})
    best = max((p["drives"] * p["rate_hz"] for p in points if p.get("pass")), default=0)
    f.append({"name": "max_axes_x_rate_per_bus", "value": best, "unit": "1/s", "better": "higher",
              "note": "highest drives x cycle rate on one bus with 0 SYNC missed"})
    return f


def measure(rates: list[int], drives: list[int], args: argparse.Namespace,
            runs: str = "runs") -> list[dict[str, Any]]:
    """Every point of ``rates`` x ``drives`` with the QEMU $SERVOAMP_QEMU
    names (refused points listed as refused); each boot's files in
    build-dir/``runs``/."""
    args.build_dir.mkdir(parents=True, exist_ok=True)
    points: list[dict[str, Any]] = []
    for rate in rates:
        period = round(1e6 / rate)
        # a point the build refuses (the generator's worst-case check,
        # reproduced here so that no firmware is built just to be refused)
        runnable: list[int] = []
        for n in drives:
            nominal, worst = analytic_bits(n)
            budget = BITRATE * period // 1_000_000
            if worst > budget:
                why = (f"{n} axes need up to {worst} bit times per cycle, {budget} available at "
                       f"{BITRATE} bit/s and {period} us")
                points.append({"drives": n, "period_us": period, "rate_hz": rate, "refused": why,
                               "pass": False, "analytic_bits": {"nominal_unstuffed": nominal, "worst_case": worst}})
                print(f"{rate} Hz, {n} drives/bus: refused by the build: {why}", flush=True)
            else:
                runnable.append(n)
        for cfg2 in boots_for(runnable):
            b = build(period, cfg2, args.build_dir, args.jobs)
            if not b.ok:
                raise RuntimeError(f"{cfg2} at {period} us refused: {b.why}")
            wd = args.build_dir / runs / b.dir.parent.name
            shutil.rmtree(wd, ignore_errors=True)
            wd.mkdir(parents=True)
            t0 = time.monotonic()
            with open(wd / "uart1.log", "w") as log:
                res = run_boot(b, args.cycles, wd, log)
            for bus, p in res.items():
                p["bus_index"] = bus
                points.append(p)
                bl = p["bus"]
                print(f"{rate} Hz, {p['drives']} drives on can{bus}: sync {p['stats']['sync']} missed "
                      f"{p['stats']['sync_missed']} pdo_missing {p['stats']['pdo_missing']}; "
                      f"bits/cycle {bl.get('bits_mean')} (max {bl.get('bits_max')}) load {bl.get('load_mean_pct')} % "
                      f"(firmware estimate {p['firmware_load_permille']} permille) "
                      f"[{time.monotonic() - t0:.0f} s]", flush=True)
    return points


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cycles", type=int, default=2000, help="window per point, cycles (a multiple of 1000)")
    ap.add_argument("--rates", default="1000,2000,4000", help="cycle rates, Hz")
    ap.add_argument("--drives", default="1-5", help="drives per bus to try")
    ap.add_argument("--quick", action="store_true", help="1 kHz, 1-2 drives, 1000 cycles (a smoke run)")
    ap.add_argument("--json", type=Path)
    ap.add_argument("--build-dir", type=Path, default=REPO / "build" / "bench" / "fieldbus")
    ap.add_argument("-j", "--jobs", type=int, default=2)
    ap.add_argument("--baseline-qemu", type=Path, metavar="QEMU",
                    help="also run every point with this qemu-system-aarch64 (the build before a change), "
                         "in the same run: the SYNC jitter figures' notes give its figure, 'baseline' its "
                         "SYNC jitter per point")
    ap.add_argument("--baseline-label", default="the baseline QEMU", help="what --baseline-qemu is, for the notes")
    ap.add_argument("--tap", type=Path, help=argparse.SUPPRESS)  # internal: the bus client (--json: its file)
    args = ap.parse_args(argv)
    if args.tap:
        return tap(args.tap, args.json)
    if args.quick:
        args.rates, args.drives, args.cycles = "1000", "1-2", 1000
    os.environ.setdefault("PYTHONPATH", str(REPO / "python"))
    if str(REPO / "python") not in os.environ["PYTHONPATH"].split(os.pathsep):
        os.environ["PYTHONPATH"] = os.pathsep.join([str(REPO / "python"), os.environ["PYTHONPATH"]])
    from servoamp import qemu

    if not os.environ.get("SERVOAMP_QEMU"):
        os.environ["SERVOAMP_QEMU"] = str(qemu.project_qemu() / "bin" / qemu.QEMU_ANY_BOARD)
    rates = parse_range(args.rates)
    drives = parse_range(args.drives)
    t_start = time.monotonic()
    points = measure(rates, drives, args)
    baseline = None
    if args.baseline_qemu:
        ours = os.environ["SERVOAMP_QEMU"]
        os.environ["SERVOAMP_QEMU"] = str(args.baseline_qemu)
        print(f"\nthe same points with {args.baseline_qemu} ({args.baseline_label})", flush=True)
        base_points = measure(rates, drives, args, runs="runs-baseline")
        os.environ["SERVOAMP_QEMU"] = ours
        baseline = {"qemu": str(args.baseline_qemu), "label": args.baseline_label,
                    "sync_jitter": {tag_of(p): j for p in base_points if (j := sync_jitter(p)) is not None}}
    points.sort(key=lambda p: (p["rate_hz"], p["drives"]))
    print()
    print(table(points, rates))
    doc = {
        "benchmark": "fieldbus",
        "command": "bench/fieldbus/can_bench.py " + " ".join(argv if argv is not None else sys.argv[1:]),
        "host": {"cpus": os.cpu_count(), "load_avg_at_start": os.getloadavg(), "machine": platform.machine()},
        "bitrate": BITRATE, "window_cycles": args.cycles,
        "host_seconds": round(time.monotonic() - t_start, 1),
        "points": points,
        "figures": figures(points, rates, baseline),
    }
    if baseline is not None:
        doc["baseline"] = baseline
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(doc, indent=1) + "\n")
        print(f"wrote {args.json}")
    return 0


def table(points: list[dict[str, Any]], rates: list[int]) -> str:
    rows = ["rate    drives  sync  missed  pdo_miss  bits/cycle mean/max  load %  fw est %  analytic % (unstuffed/worst)  result"]
    for p in points:
        a = p["analytic_bits"]
        per = p["period_us"]
        an = f"{100 * a['nominal_unstuffed'] / per:.1f} / {100 * a['worst_case'] / per:.1f}"
        if p.get("refused"):
            rows.append(f"{p['rate_hz']:>5}  {p['drives']:>6}  {'-':>4}  {'-':>6}  {'-':>8}  {'-':>19}  {'-':>6}  {'-':>8}  "
                        f"{an:>29}  refused by the build")
            continue
        bl, st = p["bus"], p["stats"]
        bits = f"{bl.get('bits_mean', '-')}/{bl.get('bits_max', '-')}"
        rows.append(f"{p['rate_hz']:>5}  {p['drives']:>6}  {st['sync']:>4}  {st['sync_missed']:>6}  {st['pdo_missing']:>8}  "
                    f"{bits:>19}  {bl.get('load_mean_pct', '-'):>6}  {p['firmware_load_permille'] / 10:>8.1f}  {an:>29}  "
                    f"{'pass' if p['pass'] else 'FAIL'}")
    rows.append("")
    for r in rates:
        ok = [p["drives"] for p in points if p["rate_hz"] == r and p.get("pass")]
        ok2 = [p["drives"] for p in points if p["rate_hz"] == r and p.get("pass") and p["stats"]["pdo_missing"] == 0]
        rows.append(f"highest passing at {r} Hz: {max(ok) if ok else 'none'} drives per bus"
                    + (f" ({max(ok) * r} axes x Hz)" if ok else "")
                    + f"; with no PDO missing either: {max(ok2) if ok2 else 'none'}")
    return "\n".join(rows)


if __name__ == "__main__":
    sys.exit(main())
