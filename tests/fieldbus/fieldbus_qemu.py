# SPDX-License-Identifier: MIT
"""The guest side of the fieldbus end-to-end tests: our QEMU's
xilinx-zynq-a9 machine with CAN0 on a bus linked to a canlink socket
(can-host-lockstep), run under qtest (-accel qtest: guest time moves only
by clock_step), its CANPS registers at 0xE0008000 read and written over the
qtest protocol, as tests/qtest/zynq-can-test.c (patch 0008) does.

The QEMU binary: $SERVOAMP_QEMU, else the project's own build; tests skip
when it has no can-host-lockstep backend.
"""

from __future__ import annotations

import os
import socket
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

import pytest

CAN0 = 0xE0008000
R_SRR, R_MSR, R_SR, R_ISR, R_IER, R_ICR = 0x00, 0x04, 0x18, 0x1C, 0x20, 0x24
R_TXID, R_TXDLC, R_TXDW1, R_TXDW2 = 0x30, 0x34, 0x38, 0x3C
R_RXID, R_RXDLC, R_RXDW1, R_RXDW2 = 0x50, 0x54, 0x58, 0x5C
SRR_CEN = 1 << 1
SR_NORMAL = 1 << 3
SR_ESTAT_ACTIVE = 1 << 7           # ESTAT 1: error active
ISR_TXOK = 1 << 1
ISR_RXOK = 1 << 4
ISR_RXNEMP = 1 << 7
IDR_SRR = 1 << 20
IDR_IDE = 1 << 19


def qemu_binary() -> str:
    """The QEMU to test, or skip if it lacks the canlink backend."""
    binary = os.environ.get("SERVOAMP_QEMU")
    if not binary:
        from servoamp import qemu
        binary = str(qemu.project_qemu() / "bin" / qemu.QEMU_ANY_BOARD)
    if not os.access(binary, os.X_OK):
        pytest.skip(f"{binary}: no QEMU")
    out = subprocess.run([binary, "-object", "help"], capture_output=True, text=True, timeout=60).stdout
    if "can-host-lockstep" not in out:
        pytest.skip(f"{binary} has no can-host-lockstep backend (docs/canlink.md)")
    return binary


@dataclass(frozen=True)
class GuestFrame:
    can_id: int
    data: bytes
    eff: bool = False
    rtr: bool = False
    dlc: int = -1

    @property
    def length(self) -> int:
        return len(self.data) if self.dlc < 0 else self.dlc


def idr(can_id: int, eff: bool, rtr: bool) -> int:
    if eff:
        return ((can_id >> 18) << 21) | ((can_id & 0x3FFFF) << 1) | IDR_IDE | IDR_SRR | int(rtr)
    return (can_id << 21) | (IDR_SRR if rtr else 0)


def from_idr(value: int) -> tuple[int, bool, bool]:
    if value & IDR_IDE:
        return ((value >> 21) << 18) | ((value >> 1) & 0x3FFFF), True, bool(value & 1)
    return value >> 21, False, bool(value & IDR_SRR)


class Board:
    """QEMU under qtest with CAN0 linked to ``can_sock``."""

    def __init__(self, binary: str, workdir: Path, bitrate: int = 1_000_000,
                 timeout_ms: int = 2000) -> None:
        self.workdir = workdir
        self.can_sock = workdir / "can0.sock"
        qtest_sock = workdir / "qtest.sock"
        self.listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self.listener.bind(str(qtest_sock))
        self.listener.listen(1)
        self.listener.settimeout(60)
        self.log = open(workdir / "qemu.log", "w")
        self.proc = subprocess.Popen(
            [binary, "-machine", "xilinx-zynq-a9,canbus0=canbus0", "-object", "can-bus,id=canbus0",
             "-object", f"can-host-lockstep,id=cl0,canbus=canbus0,path={self.can_sock},"
                        f"bitrate={bitrate},timeout-ms={timeout_ms}",
             "-accel", "qtest", "-qtest", f"unix:{qtest_sock}", "-qtest-log", "/dev/null", "-display", "none",
             "-nodefaults", "-serial", "null", "-monitor", "none"],
            stdout=self.log, stderr=subprocess.STDOUT)
        self.conn, _ = self.listener.accept()
        self.rfile = self.conn.makefile("r")
        self.bitrate = bitrate
        self.now = 0
        deadline = time.monotonic() + 30
        while not self.can_sock.exists():
            assert time.monotonic() < deadline, "QEMU made no canlink socket"
            time.sleep(0.01)

    def cmd(self, line: str) -> str:
        self.conn.sendall((line + "\n").encode())
        while True:
            answer = self.rfile.readline()
            assert answer, f"QEMU closed qtest on {line!r}: see {self.workdir / 'qemu.log'}"
            if answer.startswith("IRQ"):
                continue
            assert answer.startswith("OK"), f"{line!r}: {answer!r}"
            return answer[2:].strip()

    def writel(self, addr: int, value: int) -> None:
        self.cmd(f"writel {addr:#x} {value:#x}")

    def readl(self, addr: int) -> int:
        return int(self.cmd(f"readl {addr:#x}"), 16)

    def clock_step(self, ns: int) -> int:
        self.now = int(self.cmd(f"clock_step {ns}"))
        return self.now

    def clock_set(self, t_ns: int) -> int:
        """Run guest time up to ``t_ns`` (no-op if already there)."""
        if t_ns > self.now:
            self.clock_step(t_ns - self.now)
        return self.now

    # --- CAN0 -------------------------------------------------------------

    def can_init(self) -> None:
        self.writel(CAN0 + R_SRR, 0)
        self.writel(CAN0 + R_MSR, 0)
        self.writel(CAN0 + R_SRR, SRR_CEN)
        assert self.readl(CAN0 + R_SR) == SR_NORMAL | SR_ESTAT_ACTIVE

    def send(self, f: GuestFrame) -> None:
        """Write a frame into CAN0's TX FIFO; the model sends it on the
        write of DW2, and canlink returns when every active client's DONE
        came."""
        dlc = f.length
        data = bytes(f.data).ljust(8, b"\0")
        self.writel(CAN0 + R_TXID, idr(f.can_id, f.eff, f.rtr))
        self.writel(CAN0 + R_TXDLC, dlc << 28)
        self.writel(CAN0 + R_TXDW1, int.from_bytes(data[:4], "big"))
        self.writel(CAN0 + R_TXDW2, int.from_bytes(data[4:], "big"))
        assert self.readl(CAN0 + R_ISR) & ISR_TXOK
        self.writel(CAN0 + R_ICR, ISR_TXOK)

    def receive_all(self) -> list[GuestFrame]:
        """Every frame in CAN0's RX FIFO now."""
        out = []
        while self.readl(CAN0 + R_ISR) & ISR_RXNEMP:
            can_id, eff, rtr = from_idr(self.readl(CAN0 + R_RXID))
            dlc = self.readl(CAN0 + R_RXDLC) >> 28
            raw = self.readl(CAN0 + R_RXDW1).to_bytes(4, "big") + self.readl(CAN0 + R_RXDW2).to_bytes(4, "big")
            self.writel(CAN0 + R_ICR, ISR_RXNEMP | ISR_RXOK)
            out.append(GuestFrame(can_id, b"" if rtr else raw[:dlc], eff, rtr, dlc))
        return out

    def close(self) -> int:
        """End QEMU as libqtest does (SIGTERM: it quits cleanly and says BYE
        to the canlink clients); its exit status."""
        if self.proc.poll() is None:
            self.proc.terminate()
        try:
            self.conn.close()
            self.rfile.close()
        finally:
            self.listener.close()
        try:
            rc = self.proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            rc = self.proc.wait()
        self.log.close()
        return rc
