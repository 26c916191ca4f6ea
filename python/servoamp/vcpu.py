"""The vCPUs' state when a wait on the board times out: registers, PC and
LR symbolised, a stack scan. Part of the launcher that :mod:`servoamp.qemu`
re-exports."""

from __future__ import annotations

import re
import shutil
import subprocess
import time
from pathlib import Path
from typing import TYPE_CHECKING

from servoamp.board import REPO, Board, QemuError
from servoamp.images import kernel_link

if TYPE_CHECKING:
    from servoamp.runner import QemuMachine


ELF_MACHINE_AARCH64 = 183


class Symbols:
    """Address to ``symbol+0xoff`` for an ELF (``nm -n``), loaded once."""

    _cache: dict[Path, Symbols] = {}

    def __init__(self, elf: Path) -> None:
        self.elf = elf
        self.addrs: list[int] = []
        self.names: list[str] = []
        with elf.open("rb") as f:
            header = f.read(20)
        if header[:4] == b"\x7fELF" and int.from_bytes(header[18:20], "little") == ELF_MACHINE_AARCH64:
            nm = shutil.which("aarch64-linux-gnu-nm") or "nm"
        else:
            nm = shutil.which("arm-linux-gnueabihf-nm") or shutil.which("arm-none-eabi-nm") or "nm"
        res = subprocess.run([nm, "-n", str(elf)], text=True, capture_output=True)
        for line in res.stdout.splitlines():
            parts = line.split()
            if len(parts) == 3 and parts[1] in "tTwW" and not parts[2].startswith("$"):
                self.addrs.append(int(parts[0], 16))
                self.names.append(parts[2])

    @classmethod
    def of(cls, elf: Path) -> Symbols | None:
        if not elf.exists():
            return None
        if elf not in cls._cache:
            cls._cache[elf] = cls(elf)
        return cls._cache[elf]

    def lookup(self, addr: int) -> str | None:
        import bisect

        i = bisect.bisect_right(self.addrs, addr) - 1
        if i < 0 or addr - self.addrs[i] > 0x10000:
            return None
        return f"{self.names[i]}+{addr - self.addrs[i]:#x}"


def _vmlinux(board: Board | None) -> Path:
    """The vmlinux of the board's kernel: its own build (linux.link, the
    ZynqMP) or the Zynq-7000's variant (kernel_link)."""
    if board is not None and "link" in board.linux:
        return REPO / str(board.linux["link"]) / "obj/vmlinux"
    return kernel_link() / "obj/vmlinux"


def _symbol_files(cpu: int, board: Board | None = None) -> list[Path]:
    """Where an address of ``cpu`` may come from: CPU0 runs Linux (vmlinux)
    and servod; CPU1 the servo firmware (its ELF) or the boot stub."""
    if cpu == 0:
        return [_vmlinux(board), REPO / "build/linux/servod/servod"]
    return sorted((REPO / "build/rpu_app").glob("*/servo.elf"))


def symbolise(cpu: int, addr: int, board: Board | None = None) -> str:
    if board is not None and "boot_stub" in board.data["load"]:
        stub = board.addr("load", "boot_stub")
        if stub <= addr < stub + 0x1000:
            park = board.addr("load", "park_loop")
            return f"boot stub{' (park loop)' if addr >= park else ''}+{addr - stub:#x}"
    for f in _symbol_files(cpu, board):
        syms = Symbols.of(f)
        hit = syms.lookup(addr) if syms else None
        if hit:
            return f"{hit} ({f.name})"
    return "?"


_REG = re.compile(r"R(\d\d)=([0-9a-fA-F]{8})")
# AArch64 (the ZynqMP's A53s): PC and the link register X30
_REG64 = re.compile(r"\b(PC|X30)=([0-9a-fA-F]{16})")


def vcpu_report(machine: QemuMachine, reason: str) -> str:
    """The text of :meth:`QemuMachine.dump_state` (VM paused meanwhile)."""
    lines = [f"=== {time.strftime('%H:%M:%S')} {reason}"]
    paused = False
    try:
        machine._qmp.execute("stop")  # type: ignore[union-attr]
        paused = True
    except (QemuError, OSError) as e:
        lines.append(f"(could not pause: {e})")
    try:
        for cpu in range(int(machine.board.qemu["smp"])):
            regs = machine.hmp("info registers", cpu=cpu)
            lines.append(f"--- CPU{cpu}")
            lines.append(regs.rstrip())
            found = dict((int(n), int(v, 16)) for n, v in _REG.findall(regs))
            for n, name in ((15, "pc"), (14, "lr")):
                if n in found:
                    lines.append(f"{name} {found[n]:08x} = {symbolise(cpu, found[n], machine.board)}")
            for reg, value in _REG64.findall(regs):
                name = "pc" if reg == "PC" else "lr"
                lines.append(f"{name} {value} = {symbolise(cpu, int(value, 16), machine.board)}")
            # a stack scan: words near SP that point into code, innermost
            # first (a crude backtrace; the monitor reads through this CPU's
            # MMU). MMIO, the GIC's included, is never read from the
            # monitor: QEMU's GIC model needs a current CPU and the monitor
            # connection dies.
            if 13 in found:
                try:
                    words = machine.hmp(f"x /96wx {found[13]:#x}", cpu=cpu)
                except QemuError as e:
                    words = ""
                    lines.append(f"(stack: {e})")
                hits = []
                body = " ".join(ln.split(":", 1)[-1] for ln in words.splitlines())
                for w in re.findall(r"0x([0-9a-fA-F]{8})\b", body):
                    sym = symbolise(cpu, int(w, 16))
                    if sym != "?" and "+0x0 " not in sym and w.lower() != "ffffffff":
                        hits.append(f"  {w} {sym}")
                lines.append(f"stack scan from sp {found[13]:08x} ({len(hits)} code addresses):")
                lines.extend(hits[:40])
        # the kernel's clock as Linux sees it: jiffies stands still across
        # the two snapshots when CPU0's tick no longer arrives
        vmlinux = _vmlinux(machine.board)
        if vmlinux.exists():
            cross = "aarch64-linux-gnu-nm" if machine.board.arch == "arm64" else "arm-linux-gnueabihf-nm"
            nm = shutil.which(cross) or "nm"
            res = subprocess.run([nm, str(vmlinux)], text=True, capture_output=True)
            want: dict[str, int | None] = {"jiffies": None}
            for line in res.stdout.splitlines():
                p = line.split()
                if len(p) == 3 and p[2] in want:
                    want[p[2]] = int(p[0], 16)
            for name, addr in want.items():
                if addr is not None:
                    try:
                        out = machine.hmp(f"x /1wx {addr:#x}", cpu=0)
                        lines.append(f"{name} (CPU0) = {out.split(':', 1)[-1].strip()}")
                    except QemuError as e:
                        lines.append(f"({name}: {e})")
    finally:
        if paused:
            try:
                machine._qmp.execute("cont")  # type: ignore[union-attr]
            except (QemuError, OSError):
                pass
    return "\n".join(lines) + "\n\n"
