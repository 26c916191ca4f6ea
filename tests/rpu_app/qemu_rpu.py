# SPDX-License-Identifier: MIT
"""rpu_app without Linux (tests/rpu_app), on the project's one QEMU
launcher (servoamp.qemu): the board's machine and time base (machine_args:
virtual time by default, SERVOAMP_CLOCK=host for the host clock), its
UARTs, QMP and the monitor commands come from QemuMachine; this file adds
only what the firmware alone needs:

  - CPU0 in the test stub (build/rpu_app/<board>/qemu-stub.elf): it enables
    the GIC distributor and the global timer (what Linux would have done)
    and sleeps; the stub also holds the CPU1 park loop at the contract
    address;
  - CPU1 started in the park loop, released to the firmware entry by the
    stub (-device loader, as the remoteproc driver does on the board);
  - the gdbstub on a unix socket in the test's temporary directory: GdbRemote
    is a minimal GDB remote-serial-protocol client, the only way to WRITE
    guest physical memory from outside (the monitor has no write command),
    used to post the driver's STOP word exactly as the Linux driver would.
"""
from __future__ import annotations

import re
import time
from pathlib import Path

from servoamp import qemu

BOARD = "zynq7000_qemu"
SERVO_UART = 1          # UART1: the firmware's console (board.yaml qemu.uarts)


class GdbRemote:
    """Minimal GDB RSP client over a unix socket (acks on)."""

    def __init__(self, path: str, timeout: float = 5.0):
        self.s = qemu.connect_unix(path, timeout, "gdbstub socket")
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

    def send_packet(self, data: str) -> None:
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
    def cont(self) -> None:
        self.send_packet("c")
        self.running = True

    def interrupt(self) -> None:
        if not self.running:
            return
        self.s.sendall(b"\x03")
        reply = self._read_packet()
        if not reply.startswith(("T", "S")):
            raise ConnectionError(f"unexpected stop reply {reply!r}")
        self.running = False

    # ---- memory and registers (VM must be stopped) -------------------
    def select_cpu(self, cpu_index: int) -> None:
        r = self.command(f"Hg{cpu_index + 1:x}")
        if r != "OK":
            raise RuntimeError(f"Hg failed: {r}")

    def read_mem(self, addr: int, n: int) -> bytes:
        r = self.command(f"m{addr:x},{n:x}")
        if r.startswith("E"):
            raise RuntimeError(f"read {addr:#x}: {r}")
        return bytes.fromhex(r)

    def write_mem(self, addr: int, data: bytes) -> None:
        r = self.command(f"M{addr:x},{len(data):x}:{data.hex()}")
        if r != "OK":
            raise RuntimeError(f"write {addr:#x}: {r}")

    def read32(self, addr: int) -> int:
        return int.from_bytes(self.read_mem(addr, 4), "little")

    def write32(self, addr: int, value: int) -> None:
        self.write_mem(addr, value.to_bytes(4, "little"))

    def read_reg(self, n: int) -> int:
        r = self.command(f"p{n:x}")
        return int.from_bytes(bytes.fromhex(r), "little")


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
    """One QEMU run of the firmware alone, as a context manager."""

    def __init__(self, workdir: Path, stub: Path, firmware: Path, extra: list[str] | None = None,
                 can_links: dict[int, Path] | None = None, can_link_opts: dict[str, int] | None = None):
        self.dir = Path(workdir)
        self.dir.mkdir(parents=True, exist_ok=True)
        self.gdb_path = self.dir / "gdb.sock"
        if self.gdb_path.exists():
            self.gdb_path.unlink()
        loaders = [
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
        ]
        self.machine = qemu.QemuMachine(qemu.Board.load(BOARD), None, run_dir=self.dir, keep_logs=True,
                                        extra_args=loaders + (extra or []),
                                        can_links=can_links, can_link_opts=can_link_opts)
        self.gdb: GdbRemote | None = None

    def start(self) -> QemuRpu:
        self.machine.start()
        return self

    def attach_gdb(self) -> GdbRemote:
        if self.gdb is None:
            self.gdb = GdbRemote(str(self.gdb_path))
        return self.gdb

    def uart_text(self) -> str:
        """Everything UART1 printed so far."""
        return self.machine.uart(SERVO_UART).output

    def wait_uart(self, pattern: str, timeout: float = 5.0, count: int = 1) -> list[re.Match]:
        """The first ``count`` matches of ``pattern`` in all of UART1's output
        (from the start, not from a cursor), waiting up to ``timeout``."""
        rx = re.compile(pattern, re.M)
        deadline = time.monotonic() + timeout
        while True:
            found = list(rx.finditer(self.uart_text()))
            if len(found) >= count:
                return found
            if not self.machine.running:
                raise RuntimeError(f"QEMU exited; UART1:\n{self.uart_text()}")
            if time.monotonic() > deadline:
                raise TimeoutError(f"{pattern!r} x{count} not on UART1 after {timeout}s:\n{self.uart_text()[-3000:]}")
            time.sleep(0.02)

    def read_word(self, addr: int) -> int:
        return self.machine.read_word(addr)

    def wait_word(self, addr: int, value: int, timeout: float = 5.0) -> float:
        """Poll a word until it equals ``value``; the host seconds it took."""
        return self.machine.wait_word(addr, value, timeout=timeout, interval=0.005)

    def monitor(self, command: str) -> str:
        return self.machine.hmp(command)

    def cpu_pc(self, cpu_index: int) -> int:
        out = self.machine.hmp("info registers", cpu=cpu_index)
        m = re.search(r"R15=([0-9a-fA-F]{8})", out)
        if not m:
            raise RuntimeError(f"info registers parse: {out!r}")
        return int(m.group(1), 16)

    def stop(self) -> None:
        if self.gdb is not None:
            try:
                self.gdb.close()
            except OSError:
                pass
            self.gdb = None
        self.machine.stop()

    def __enter__(self) -> QemuRpu:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()
