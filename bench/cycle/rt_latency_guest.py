# SPDX-License-Identifier: MIT
"""The RT latency table's guest side (bench/cycle/rt_latency_bench.py): the
benchmark's images (the board's with the rt-tests overlay of its
architecture), servod's telemetry and the bulk-TCP sender on the host, one
window per load and one boot per kernel. The loads and what each figure
comes from: rt_latency_bench.py's docstring."""

from __future__ import annotations

import dataclasses
import hashlib
import os
import socket
import struct
import subprocess
import shutil
import threading
import time
from array import array
from pathlib import Path
from typing import Any, Callable, Mapping

from rt_latency_table import CT_PRIO, _us, parse_cyclictest, wake_summary
from servoamp import netboard, qemu
from servoamp import telemetry as tw

REPO = Path(__file__).resolve().parents[2]

TELEMETRY_PORT = 7700
SINK_PORT = 5001
GUEST_ADDR = "10.0.2.15"
BOOT_TIMEOUT_S = 300.0   # host seconds to the shell (the ZynqMP's TF-A boot: 1-2 min on a busy host)
TOKEN_FILE = "/tmp/telemetry.token"
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


# ---- the guest ------------------------------------------------------------------------

def board_kernels(board: qemu.Board) -> tuple[str, ...]:
    """The kernels the board boots (board.yaml linux.kernels: the
    Zynq-7000's vanilla and rt, linux/kernel/build.sh --variant; the
    ZynqMP's one PREEMPT_RT build, its linux.build); ``rt`` alone when the
    board names none."""
    names = tuple(str(k) for k in board.linux.get("kernels") or ("rt",))
    bad = [k for k in names if k not in qemu.KERNELS]
    if bad:
        raise qemu.QemuError(f"board {board.name}: linux.kernels {bad} not in {', '.join(qemu.KERNELS)}")
    return names


def kernel_dir(board: qemu.Board, kernel: str) -> Path:
    """The build directory of ``kernel`` for ``board``: the board's own
    build when it names one (linux.build: one kernel), else the variant's
    (build/kernel-rt, build/kernel)."""
    if board.linux.get("build"):
        return qemu.board_kernel_dir(board)
    return qemu.kernel_dir(kernel)


def rt_tests_overlay(arch: str) -> Path:
    """linux/initramfs/build-rt-tests.sh's archive for the Debian
    architecture ``arch`` (cached by its debs)."""
    res = subprocess.run([str(REPO / "linux/initramfs/build-rt-tests.sh"), "--arch", arch, "--print"],
                         text=True, stdout=subprocess.PIPE, check=True)
    return Path(res.stdout.strip().splitlines()[-1])


def bench_images(board: qemu.Board, kernel: str, out_dir: Path) -> qemu.Images:
    """The board's images for ``kernel`` (qemu.prepare_images: the stub or
    TF-A's chain, the board's modules, its test firmware and rpu_app), with
    the rt-tests overlay of the board's architecture concatenated to the
    initramfs and a DTB of this benchmark's own whose /chosen spans both."""
    os.environ["SERVOAMP_KERNEL"] = kernel
    images = qemu.prepare_images(board)
    overlay = rt_tests_overlay(qemu.guest_arch(board))
    out_dir.mkdir(parents=True, exist_ok=True)
    combined = out_dir / "initramfs-rt-tests.cpio.gz"
    with combined.open("wb") as f:
        for part in (images.initramfs, overlay):
            with part.open("rb") as g:
                shutil.copyfileobj(g, f)
    dtb = qemu.build_dtb(board, qemu.kernel_source(kernel_dir(board, kernel)), combined, out_dir=out_dir)
    return dataclasses.replace(images, dtb=dtb, initramfs=combined)


def nic_args(board: qemu.Board, telemetry_port: int, sink_port: int) -> list[str]:
    """gem0 on QEMU user networking (the board's network.nic), servod's
    telemetry and the net load's sink forwarded from 127.0.0.1."""
    model = str((board.data.get("network") or {}).get("nic", "cadence_gem"))
    return ["-nic", f"user,model={model},hostfwd=tcp:127.0.0.1:{telemetry_port}-:{TELEMETRY_PORT},"
                    f"hostfwd=tcp:127.0.0.1:{sink_port}-:{SINK_PORT}"]


def servod_board_args(board: qemu.Board) -> str:
    """servod's options that name the board (as python/servoamp/netboard.py
    gives them): its id in the telemetry's HELLO, the servo's time base."""
    hz = board.servo.get("clock_hz")
    return f"--id {board.name}" + (f" --servo-clock-hz {int(hz)}" if hz else "")


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
        # the sink's job, its process group (the console's shell has job
        # control): not `killall nc sleep`, after which the shell once ended
        # the rest of its command line (a 100,000-cycle run, 2026-11-29)
        sh("p=$(cat /tmp/sink.pid); kill -TERM -$p 2>/dev/null; wait $p 2>/dev/null; true")
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
    info = (images.kernel.parent / "info").read_text()
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
    m = qemu.QemuMachine(board, images, accel="tcg,thread=single", clock="virtual",
                         extra_args=nic_args(board, tport, nport))
    out: dict[str, Any] = {"kernel": kernel, "board": board.name, "kernelrelease": "", "build": ident,
                           "rates": {}}
    token = os.urandom(16).hex()
    with m:
        qemu.boot_to_shell(m, timeout=BOOT_TIMEOUT_S)
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
        sh(f"(servod {servod_board_args(board)} --telemetry {GUEST_ADDR}:{TELEMETRY_PORT} "
           f"--telemetry-token {TOKEN_FILE} "
           "> /tmp/servod.log 2>&1 &)")
        sh("while ! grep -q 'waiting for the servo' /tmp/servod.log; do sleep 0.05; done")
        # the servo core's remoteproc, found by servod (netboard.FIND_RPROC;
        # find_rproc says why when there is none)
        rproc = netboard.find_rproc(lambda cmd: qemu.run_shell(c, cmd, prompt, timeout=60.0)[1])
        sh(f"echo rpu_app.elf > {rproc}/firmware; echo start > {rproc}/state")
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
