#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""servod's wake-up latency and cyclictest on both kernels, at 1 and 4 kHz,
idle and with Linux loaded (issue 23, item 2; printed, not asserted).

    .venv/bin/python bench/cycle/rt_latency_bench.py [--cycles 100000]
        [--kernels vanilla,rt] [--rates 1000,4000]
        [--loads idle,hackbench,cpu,net,recovery]
        [--json bench/results/rt_latency.json] [--jobs 2] [--resume]
    .venv/bin/python bench/cycle/rt_latency_bench.py --merge A.json B.json... [--json OUT]

``--jobs 2`` boots both kernels at once (each QEMU runs on one host core:
on two free cores the wall time halves). ``--resume`` keeps the windows an
interrupted run saved in its partial file (build/bench/rt_latency/
<json stem>.partial.json, written after every window) when it was measured
with the same --cycles, QEMU and kernel builds, and measures only the
others: the 100,000-cycle table needs about 4.7 h of one core, more than
one sitting on a shared host. Every window records its build (kernel key,
initramfs hash) and when it was measured.

For each kernel (linux/kernel/build.sh --variant; SERVOAMP_KERNEL) one boot
of zynq7000_qemu on virtual time (-icount shift=0: 1 instruction = 1 guest
ns, host load does not enter), all kernels in one run of this script. The
boot's initramfs is the board's own with the rt-tests overlay
(linux/initramfs/build-rt-tests.sh: cyclictest, hackbench and their glibc)
concatenated to it, in an image and a DTB of this benchmark's own
(build/bench/rt_latency/<kernel>/); the board's images are not changed.
eth0 is up on QEMU user networking with two forwarded ports: servod's
telemetry (7700) and a sink for the ``net`` load (5001).

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
1 us histogram (-h).

Where each figure comes from:

- servod wake-up min / p99 / p99.99 / max: every cycle's
  ``wake_latency_ns`` (the cycle interrupt's event to servod's cycle thread
  running, read from TTC1's counter) in servod's telemetry stream, read on
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
preemption, not a Zynq-7000's microseconds.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import hashlib
import json
import math
import os
import platform
import re
import shutil
import signal
import socket
import struct
import subprocess
import sys
import threading
import time
from array import array
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "python"))

from servoamp import qemu  # noqa: E402
from servoamp import telemetry as tw  # noqa: E402

TELEMETRY_PORT = 7700
SINK_PORT = 5001
GUEST_ADDR = "10.0.2.15"
TOKEN_FILE = "/tmp/telemetry.token"
CT_PRIO = 70
CT_HIST_US = 1000
HACKBENCH = "hackbench -g 2 -l 200"

LOADS: dict[str, list[str]] = {
    "idle": [],
    "hackbench": [f"while :; do {HACKBENCH} >/dev/null 2>&1; done"],
    "cpu": ["while :; do :; done"],
    "net": [],          # the host's sender; the guest's sink runs for the whole boot
    "recovery": [],     # ampctl debug hang at the window's start
    "fork-fs": ["while :; do ls -R /sys >/dev/null 2>&1; done"] * 2,
}
DEFAULT_LOADS = ("idle", "hackbench", "cpu", "net", "recovery")


# ---- host-side computations (tests/bench/test_rt_latency_bench.py) --------------------

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


# ---- the guest ------------------------------------------------------------------------

def bench_images(board: qemu.Board, kernel: str, out_dir: Path) -> qemu.Images:
    """The board's images for ``kernel`` (as qemu.prepare_images builds
    them), with the rt-tests overlay concatenated to the initramfs and a DTB
    of this benchmark's own whose /chosen spans both."""
    os.environ["SERVOAMP_KERNEL"] = kernel
    kdir = qemu.kernel_dir(kernel)
    modules = qemu.build_modules(kdir)
    firmware = qemu.build_test_firmware() + qemu.rpu_app_firmware(board)
    base = qemu.build_initramfs(modules, firmware, qemu.build_userland())
    res = subprocess.run([str(REPO / "linux/initramfs/build-rt-tests.sh"), "--print"],
                         text=True, stdout=subprocess.PIPE, check=True)
    overlay = Path(res.stdout.strip().splitlines()[-1])
    out_dir.mkdir(parents=True, exist_ok=True)
    combined = out_dir / "initramfs-rt-tests.cpio.gz"
    with combined.open("wb") as f:
        for part in (base, overlay):
            with part.open("rb") as g:
                shutil.copyfileobj(g, f)
    dtb = qemu.build_dtb(board, qemu.kernel_source(kdir), combined, out_dir=out_dir)
    return qemu.Images(stub=qemu.build_stub(board), zimage=kdir / "zImage", dtb=dtb, initramfs=combined,
                       firmware=tuple(firmware), stub_icount=qemu.build_stub(board, park_wfe=False))


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Telemetry(threading.Thread):
    """servod's telemetry through the forwarded port: every CYCLE's
    (cycle number, wake_latency_ns), and the GAPs."""

    WAKE = struct.Struct("<Q20xI")   # cycle at 0, wake-up latency (ns) at 28

    def __init__(self, port: int, token: str) -> None:
        super().__init__(daemon=True)
        self.port, self.token = port, token
        self.cycles = array("Q")
        self.wake = array("I")
        self.gaps: list[dict[str, Any]] = []
        self.connections = 0
        self.error = ""
        self.stop_ev = threading.Event()
        self.lock = threading.Lock()

    def last_cycle(self) -> int:
        with self.lock:
            return int(self.cycles[-1]) if self.cycles else -1

    def between(self, a: int, b: int) -> list[int]:
        """wake_latency_ns of the cycles a < cycle <= b received."""
        with self.lock:
            return [w for c, w in zip(self.cycles, self.wake) if a < c <= b]

    def run(self) -> None:
        while not self.stop_ev.is_set():
            try:
                with socket.create_connection(("127.0.0.1", self.port), timeout=5.0) as s:
                    s.settimeout(1.0)
                    s.sendall(tw.encode_auth(self.token))
                    self.connections += 1
                    sp = tw.FrameSplitter()
                    while not self.stop_ev.is_set():
                        try:
                            data = s.recv(1 << 16)
                        except socket.timeout:
                            continue
                        if not data:
                            break
                        sp.feed(data)
                        for typ, off, ln in sp.frames():
                            if typ == tw.MSG_CYCLE:
                                c, w = self.WAKE.unpack_from(sp.buf, off)
                                with self.lock:
                                    self.cycles.append(c)
                                    self.wake.append(w)
                            elif typ == tw.MSG_GAP:
                                g = tw.decode_gap(bytes(sp.buf[off:off + ln]))
                                self.gaps.append({"from": g.from_cycle, "to": g.to_cycle, "count": g.count,
                                                  "reason": g.reason})
            except OSError as e:
                self.error = str(e)
            self.stop_ev.wait(0.5)


class Sender(threading.Thread):
    """Bulk TCP to the guest's sink through the forwarded port (the net load)."""

    def __init__(self, port: int) -> None:
        super().__init__(daemon=True)
        self.port = port
        self.sent = 0
        self.stop_ev = threading.Event()

    def run(self) -> None:
        chunk = b"\0" * 65536
        while not self.stop_ev.is_set():
            try:
                with socket.create_connection(("127.0.0.1", self.port), timeout=5.0) as s:
                    s.settimeout(1.0)
                    while not self.stop_ev.is_set():
                        try:
                            self.sent += s.send(chunk)
                        except socket.timeout:
                            continue
            except OSError:
                pass
            self.stop_ev.wait(0.2)


def stats(sh: Callable[..., str]) -> dict[str, str]:
    out = sh("ampctl stats", 120)
    return {l.split("=", 1)[0]: l.split("=", 1)[1] for l in out.splitlines() if "=" in l}


def window(sh: Callable[..., str], tel: Telemetry, nport: int, load: str, cycles: int,
           period_us: int) -> dict[str, Any]:
    seconds = cycles * period_us / 1e6
    for loop in LOADS[load]:
        sh(f"({loop}) >/dev/null 2>&1 & echo $! >> /tmp/load.pids")
    sender = None
    if load == "net":
        # the guest's sink, one per window; nc reads its stdin too: a pipe
        # that never delivers (a background job reading the console is
        # stopped by SIGTTIN, and the transfer with it)
        sh(f"(sleep 100000 | nc -l -p {SINK_PORT} > /dev/null 2>&1) & echo $! > /tmp/sink.pid")
        sender = Sender(nport)
        sender.start()
    sh("rm -f /tmp/ct.txt; (cyclictest -m -q -p %d -i %d -l %d -h %d > /tmp/ct.txt 2>&1; echo done >> /tmp/ct.txt) & echo $! > /tmp/ct.pid"
       % (CT_PRIO, period_us, cycles, CT_HIST_US))
    a = stats(sh)
    t0 = time.monotonic()
    if load == "recovery":
        sh("ampctl debug hang")
    sh(f"sleep {seconds:g}", seconds * 200 + 120)
    host = time.monotonic() - t0
    b = stats(sh)
    # cyclictest started a little before the window: let it end
    sh("while ! grep -q '^done' /tmp/ct.txt; do sleep 0.05; done", seconds * 50 + 120)
    host_total = time.monotonic() - t0
    ct_text = sh("grep -v ' 000000$' /tmp/ct.txt; true", 120)
    if sender:
        sender.stop_ev.set()
        sender.join(5)
        sh("killall nc sleep 2>/dev/null; true")
    if LOADS[load]:
        sh("kill $(cat /tmp/load.pids); rm -f /tmp/load.pids; sleep 0.2; killall hackbench 2>/dev/null; true")

    def delta(k: str) -> int:
        return int(b.get(k, "0"), 0) - int(a.get(k, "0"), 0)

    c0, c1 = int(a["linux.cycles"], 0), int(b["linux.cycles"], 0)
    deadline = time.monotonic() + 60
    while tel.last_cycle() < c1 and time.monotonic() < deadline:
        time.sleep(0.2)
    wake = tel.between(c0, c1)
    hist = {k.split(".", 2)[2]: delta(k) for k in b if k.startswith("linux.wake_lat_hist.")}
    out: dict[str, Any] = {
        "period_us": period_us,
        "guest_seconds": seconds,
        "host_seconds": round(host, 1),
        "host_seconds_with_cyclictest_end": round(host_total, 1),
        "cycles": c1 - c0,
        "missed": delta("linux.missed_irq"),
        "late": delta("linux.late"),
        "recoveries": delta("linux.recoveries"),
        "servod_wake_ns": wake_summary(wake),
        "servod_histogram": hist,
        "cyclictest": parse_cyclictest(ct_text),
    }
    if sender:
        out["net_bytes_sent_by_host"] = sender.sent
    return out


def build_identity(kernel: str, images: qemu.Images) -> dict[str, str]:
    """What a window's figures depend on besides the guest's own code: the
    kernel build (its cache key) and the initramfs (servod, the firmware)."""
    info = (images.zimage.parent / "info").read_text()
    key = next((ln.split("=", 1)[1] for ln in info.splitlines() if ln.startswith("key=")), "")
    return {"kernel": kernel, "kernel_key": key,
            "initramfs_sha256": hashlib.sha256(images.initramfs.read_bytes()).hexdigest()[:16]}


def run_kernel(board: qemu.Board, kernel: str, images: qemu.Images, cycles: int, rates: list[int],
               loads: list[str], save: Callable[[dict[str, Any]], None] = lambda _k: None,
               done: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """One boot of ``kernel``: every rate and load; ``save`` gets the
    kernel's results after every window (a partial results file). ``done``:
    this kernel's results of an interrupted run (--resume): its windows are
    kept and not measured again; nothing is booted if none is left."""
    ident = build_identity(kernel, images)
    kept = {r: dict((done or {}).get("rates", {}).get(str(r), {}).get("windows", {})) for r in rates}
    if all(name in kept[r] for r in rates for name in loads):
        print(f"[{kernel:7}] every window kept from the interrupted run", flush=True)
        return dict(done or {})
    prompt = str(board.data["linux"]["prompt"])
    tport, nport = free_port(), free_port()
    nic = ["-nic", f"user,model=cadence_gem,hostfwd=tcp:127.0.0.1:{tport}-:{TELEMETRY_PORT},"
                   f"hostfwd=tcp:127.0.0.1:{nport}-:{SINK_PORT}"]
    m = qemu.QemuMachine(board, images, accel="tcg,thread=single", clock="virtual", extra_args=nic)
    out: dict[str, Any] = {"kernel": kernel, "kernelrelease": "", "build": ident, "rates": {}}
    token = os.urandom(16).hex()
    with m:
        qemu.boot_to_shell(m, timeout=180)
        c = m.uart(0)

        def sh(cmd: str, t: float = 60.0) -> str:
            rc, text = qemu.run_shell(c, cmd, prompt, timeout=t)
            if rc:
                raise RuntimeError(f"{cmd!r} failed ({rc}):\n{text}")
            return str(text)

        out["kernelrelease"] = sh("uname -r").strip()
        sh("dmesg -n 1")
        sh(f"servoamp-net {GUEST_ADDR}/24", 60)
        out["rt_tests"] = sh("cyclictest --help 2>&1 | head -1; hackbench --help 2>&1 | head -1; true")
        sh(f"umask 077; echo {token} > {TOKEN_FILE}")
        sh(f"(servod --telemetry {GUEST_ADDR}:{TELEMETRY_PORT} --telemetry-token {TOKEN_FILE} "
           "> /tmp/servod.log 2>&1 &)")
        sh("while ! grep -q 'waiting for the servo' /tmp/servod.log; do sleep 0.05; done")
        sh("echo rpu_app.elf > /sys/class/remoteproc/remoteproc0/firmware; "
           "echo start > /sys/class/remoteproc/remoteproc0/state")
        sh("while ! grep -q 'parameter set loaded' /tmp/servod.log; do sleep 0.05; done")
        sh("ampctl param set wd_limit 50; ampctl resume; true")
        tel = Telemetry(tport, token)
        tel.start()
        # every real-time thread: name, rt_priority, policy (1 = SCHED_FIFO)
        out["threads"] = sh("for p in /proc/[0-9]*/task/[0-9]*; do s=$(cut -d' ' -f40,41 $p/stat 2>/dev/null); "
                            "case $s in ''|*' 0') ;; *) echo \"$(cat $p/comm) $s\";; esac; done; true")
        try:
            for rate in rates:
                period_us = 1_000_000 // rate
                sh(f"ampctl param set cycle_period_us {period_us}")
                sh("sleep 0.5")
                r: dict[str, Any] = {"period_us": period_us, "windows": {}}
                out["rates"][str(rate)] = r
                for name in loads:
                    if name in kept[rate]:
                        r["windows"][name] = kept[rate][name]
                        continue
                    w = window(sh, tel, nport, name, cycles, period_us)
                    w["build"] = ident
                    w["measured_at"] = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
                    r["windows"][name] = w
                    save(out)
                    s, ct = w["servod_wake_ns"], w["cyclictest"]
                    print(f"[{kernel:7} {rate} Hz {name:9}] cycles {w['cycles']} records {s.get('n', 0)} "
                          f"missed {w['missed']} late {w['late']} recoveries {w['recoveries']}; wake-up us "
                          f"min {_us(s.get('min'))} p99 {_us(s.get('p99'))} p99.99 {_us(s.get('p9999'))} "
                          f"max {_us(s.get('max'))}; cyclictest min/avg/max {ct.get('min')}/{ct.get('avg')}/"
                          f"{ct.get('max')} p99.99 {ct.get('p9999')} ({w['host_seconds']} s host)", flush=True)
        finally:
            tel.stop_ev.set()
            tel.join(5)
            out["telemetry"] = {"connections": tel.connections, "records": len(tel.cycles), "gaps": tel.gaps,
                                "error": tel.error}
            out["servod_log_tail"] = sh("tail -n 20 /tmp/servod.log; true")
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


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cycles", type=int, default=10_000,
                    help="cycles per window and rate (default: %(default)s; the committed results: 100000)")
    ap.add_argument("--kernels", default="vanilla,rt")
    ap.add_argument("--rates", default="1000,4000", help="cycle rates in Hz (default: %(default)s)")
    ap.add_argument("--loads", default=",".join(DEFAULT_LOADS))
    ap.add_argument("--json", type=Path, default=REPO / "bench/results/rt_latency.json")
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
    kernels = args.kernels.split(",")
    for kernel in kernels:
        if kernel not in qemu.KERNELS:
            ap.error(f"--kernels: {kernel!r} is not one of {', '.join(qemu.KERNELS)}")
    board = qemu.Board.load("zynq7000_qemu")
    result: dict[str, Any] = {
        "command": "bench/cycle/rt_latency_bench.py " + " ".join(sys.argv[1:]),
        "host": {"cpus": os.cpu_count(), "load_avg_at_start": os.getloadavg(), "machine": platform.machine()},
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
    images = {k: bench_images(board, k, REPO / "build/bench/rt_latency" / k) for k in kernels}
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
