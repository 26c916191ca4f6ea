# SPDX-License-Identifier: MIT
"""QEMU harness for rpu_app without Linux (tests/rpu_app).

Runs `qemu-system-arm -M xilinx-zynq-a9 -smp 2 -m 512M` with:
  - CPU0 in the test stub (build/rpu_app/<board>/qemu-stub.elf): it enables
    the GIC distributor and the global timer (what Linux would have done)
    and sleeps; the stub also holds the CPU1 park loop at the contract
    address;
  - CPU1 started directly at the firmware entry (-device loader,cpu-num=1);
  - UART1 (-serial #1) written to a file, UART0 discarded;
  - the HMP monitor and the gdbstub on unix sockets in the test's temporary
    directory (nothing listens on a network port).

GdbRemote is a minimal GDB remote-serial-protocol client: the only way to
WRITE guest physical memory from outside (HMP has no write command), used
to post the driver's STOP word exactly as the Linux driver would.
"""
from __future__ import annotations

import os
import re
import shutil
import socket
import subprocess
import time
from pathlib import Path



def qemu_binary() -> str:
    """The same QEMU as every board run: the project's own build
    (servoamp.qemu.check_qemu; $SERVOAMP_QEMU overrides it)."""
    from servoamp import qemu
    return qemu.check_qemu(qemu.Board.load("zynq7000_qemu"))


def _connect_unix(path: str, timeout: float) -> socket.socket:
    """Connect to a unix socket QEMU is still creating, retrying until timeout."""
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    s.settimeout(timeout)
    deadline = time.monotonic() + timeout
    while True:
        try:
            s.connect(path)
            return s
        except (FileNotFoundError, ConnectionRefusedError):
            if time.monotonic() > deadline:
                s.close()
                raise
            time.sleep(0.02)


class GdbRemote:
    """Minimal GDB RSP client over a unix socket (acks on)."""

    def __init__(self, path: str, timeout: float = 5.0):
        self.s = _connect_unix(path, timeout)
        self.buf = b""
        self.running = False
        # QEMU stops the VM when a debugger attaches; ask why (sync point).
        self.command("?")

    def close(self):
        try:
            if not self.running:
                self.send_packet("D")  # detach: the VM resumes
                self._read_packet()
        except OSError:
            pass
        self.s.close()

    def _recv(self) -> bytes:
        d = self.s.recv(4096)
        if not d:
            raise ConnectionError("gdbstub closed the connection")
        return d

    def send_packet(self, data: str):
        cs = sum(data.encode()) & 0xFF
        pkt = f"${data}#{cs:02x}".encode()
        for _ in range(3):
            self.s.sendall(pkt)
            while True:
                while not self.buf:
                    self.buf += self._recv()
                c, self.buf = self.buf[:1], self.buf[1:]
                if c == b"+":
                    return
                if c == b"-":
                    break  # resend
                # anything else before the ack: ignore (e.g. stray '%')
        raise ConnectionError("gdbstub did not acknowledge")

    def _read_packet(self) -> str:
        while True:
            start = self.buf.find(b"$")
            if start >= 0:
                end = self.buf.find(b"#", start)
                if end >= 0 and len(self.buf) >= end + 3:
                    data = self.buf[start + 1:end]
                    self.buf = self.buf[end + 3:]
                    self.s.sendall(b"+")
                    return data.decode()
            self.buf += self._recv()

    def command(self, data: str) -> str:
        self.send_packet(data)
        return self._read_packet()

    # ---- execution control ------------------------------------------
    def cont(self):
        self.send_packet("c")
        self.running = True

    def interrupt(self):
        if not self.running:
            return
        self.s.sendall(b"\x03")
        reply = self._read_packet()
        if not reply.startswith(("T", "S")):
            raise ConnectionError(f"unexpected stop reply {reply!r}")
        self.running = False

    # ---- memory and registers (VM must be stopped) -------------------
    def select_cpu(self, cpu_index: int):
        r = self.command(f"Hg{cpu_index + 1:x}")
        if r != "OK":
            raise RuntimeError(f"Hg failed: {r}")

    def read_mem(self, addr: int, n: int) -> bytes:
        r = self.command(f"m{addr:x},{n:x}")
        if r.startswith("E"):
            raise RuntimeError(f"read {addr:#x}: {r}")
        return bytes.fromhex(r)

    def write_mem(self, addr: int, data: bytes):
        r = self.command(f"M{addr:x},{len(data):x}:{data.hex()}")
        if r != "OK":
            raise RuntimeError(f"write {addr:#x}: {r}")

    def read32(self, addr: int) -> int:
        return int.from_bytes(self.read_mem(addr, 4), "little")

    def write32(self, addr: int, value: int):
        self.write_mem(addr, value.to_bytes(4, "little"))

    def read_reg(self, n: int) -> int:
        r = self.command(f"p{n:x}")
        return int.from_bytes(bytes.fromhex(r), "little")


class Hmp:
    """HMP monitor over a unix socket."""

    PROMPT = b"(qemu) "

    def __init__(self, path: str, timeout: float = 5.0):
        self.s = _connect_unix(path, timeout)
        self._until_prompt()

    def _until_prompt(self) -> str:
        buf = b""
        while not buf.endswith(self.PROMPT):
            d = self.s.recv(4096)
            if not d:
                raise ConnectionError("monitor closed")
            buf += d
        return buf[: -len(self.PROMPT)].decode(errors="replace")

    def cmd(self, line: str) -> str:
        self.s.sendall(line.encode() + b"\n")
        out = self._until_prompt()
        # drop the echoed command line (HMP echoes with terminal escapes)
        return out.split("\n", 1)[1] if "\n" in out else ""

    def xp32(self, addr: int) -> int:
        out = self.cmd(f"xp /1wx {addr:#x}")
        m = re.search(r":\s*0x([0-9a-fA-F]+)", out)
        if not m:
            raise RuntimeError(f"xp parse: {out!r}")
        return int(m.group(1), 16)

    def cpu_pc(self, cpu_index: int) -> int:
        self.cmd(f"cpu {cpu_index}")
        out = self.cmd("info registers")
        m = re.search(r"R15=([0-9a-fA-F]{8})", out)
        if not m:
            raise RuntimeError(f"info registers parse: {out!r}")
        return int(m.group(1), 16)

    def close(self):
        self.s.close()


def _elf_entry(path: Path) -> int:
    from elftools.elf.elffile import ELFFile

    with open(path, "rb") as f:
        return int(ELFFile(f).header["e_entry"])


def _symbol(path: Path, name: str) -> int:
    from elftools.elf.elffile import ELFFile

    with open(path, "rb") as f:
        symtab = ELFFile(f).get_section_by_name(".symtab")
        syms = symtab.get_symbol_by_name(name) if symtab else None
        if not syms:
            raise KeyError(f"{name} not in {path}")
        return int(syms[0]["st_value"])


class QemuRpu:
    def __init__(self, workdir: Path, stub: Path, firmware: Path, extra: list[str] | None = None):
        self.dir = Path(workdir)
        self.dir.mkdir(parents=True, exist_ok=True)
        self.uart1 = self.dir / "uart1.log"
        self.mon_path = str(self.dir / "mon.sock")
        self.gdb_path = str(self.dir / "gdb.sock")
        for p in (self.uart1, Path(self.mon_path), Path(self.gdb_path)):
            if p.exists():
                p.unlink()
        self.argv = [
            qemu_binary(), "-M", "xilinx-zynq-a9", "-smp", "2", "-m", "512M",
            "-display", "none", "-nodefaults",
            "-chardev", "null,id=uart0",
            "-chardev", f"file,id=uart1,path={self.uart1}",
            "-serial", "chardev:uart0", "-serial", "chardev:uart1",
            "-chardev", f"socket,id=mon,path={self.mon_path},server=on,wait=off",
            "-mon", "chardev=mon,mode=readline",
            "-chardev", f"socket,id=gdb,path={self.gdb_path},server=on,wait=off",
            "-gdb", "chardev:gdb",
            # CPU0 runs the stub; CPU1 waits in the park loop until CPU0 has
            # set up the timer and writes the firmware entry to the boot
            # register, as the remoteproc driver does on the board
            "-device", f"loader,file={stub},cpu-num=0",
            "-device", f"loader,file={firmware}",
            "-device", f"loader,addr={_symbol(stub, 'park_loop'):#x},cpu-num=1",
            "-device", f"loader,addr={_symbol(stub, 'stub_fw_entry'):#x},"
                       f"data={_elf_entry(firmware):#x},data-len=4",
        ] + (extra or [])
        self.proc: subprocess.Popen | None = None
        self.hmp: Hmp | None = None
        self.gdb: GdbRemote | None = None
        self.t0 = 0.0

    def start(self):
        self.stderr = open(self.dir / "qemu.stderr", "w")
        self.proc = subprocess.Popen(self.argv, stdin=subprocess.DEVNULL,
                                     stdout=self.stderr, stderr=subprocess.STDOUT)
        self.t0 = time.monotonic()
        self.hmp = Hmp(self.mon_path)
        return self

    def attach_gdb(self) -> GdbRemote:
        if self.gdb is None:
            self.gdb = GdbRemote(self.gdb_path)
        return self.gdb

    def uart_text(self) -> str:
        try:
            return self.uart1.read_text(errors="replace").replace("\r", "")
        except FileNotFoundError:
            return ""

    def wait_uart(self, pattern: str, timeout: float = 5.0, count: int = 1) -> list[re.Match]:
        rx = re.compile(pattern, re.M)
        deadline = time.monotonic() + timeout
        while True:
            found = list(rx.finditer(self.uart_text()))
            if len(found) >= count:
                return found
            if self.proc.poll() is not None:
                raise RuntimeError(f"QEMU exited ({self.proc.returncode}); UART1:\n{self.uart_text()}")
            if time.monotonic() > deadline:
                raise TimeoutError(f"{pattern!r} x{count} not on UART1 after {timeout}s:\n{self.uart_text()[-3000:]}")
            time.sleep(0.02)

    def wait_word(self, addr: int, value: int, timeout: float = 5.0) -> float:
        deadline = time.monotonic() + timeout
        t = time.monotonic()
        while True:
            v = self.hmp.xp32(addr)
            if v == value:
                return time.monotonic() - t
            if time.monotonic() > deadline:
                raise TimeoutError(f"[{addr:#x}] = {v:#010x}, wanted {value:#010x}")
            time.sleep(0.005)

    def stop(self):
        for c in (self.gdb, self.hmp):
            if c is not None:
                try:
                    c.close()
                except OSError:
                    pass
        self.gdb = self.hmp = None
        if self.proc and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(timeout=5)
        if getattr(self, "stderr", None):
            self.stderr.close()

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()
