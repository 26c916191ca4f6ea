"""The board description: ``boards/<board>/board.yaml`` (its numbers: QEMU
machine, memory map, load addresses, UARTs), and what every part of the
launcher shares (:class:`QemuError`, the repository root). Part of the
launcher that :mod:`servoamp.qemu` re-exports."""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml  # type: ignore[import-untyped]

REPO = Path(__file__).resolve().parents[2]


class QemuError(RuntimeError):
    """QEMU could not be started, or a wait on the board timed out."""


def _log(msg: str) -> None:
    print(f"[qemu] {msg}", flush=True)


# --------------------------------------------------------------------------
# Board description
# --------------------------------------------------------------------------


@dataclass(frozen=True)
class Board:
    """A board folder with its ``board.yaml``."""

    name: str
    folder: Path
    data: dict[str, Any]

    @classmethod
    def load(cls, name_or_path: str | Path = "zynq7000_qemu") -> Board:
        path = Path(name_or_path)
        if not path.exists():
            path = REPO / "boards" / str(name_or_path)
        if path.is_dir():
            path = path / "board.yaml"
        data = yaml.safe_load(path.read_text())
        if not isinstance(data, dict):
            raise QemuError(f"{path}: not a mapping")
        return cls(name=str(data["name"]), folder=path.parent, data=data)

    def addr(self, *keys: str) -> int:
        """A number from the board file, e.g. ``addr("load", "zimage")``."""
        node: Any = self.data
        for k in keys:
            node = node[k]
        if not isinstance(node, int):
            raise QemuError(f"board {self.name}: {'.'.join(keys)} is not a number")
        return node

    @property
    def qemu(self) -> dict[str, Any]:
        q = self.data["qemu"]
        assert isinstance(q, dict)
        return q

    @property
    def build_dir(self) -> Path:
        return REPO / "build" / "boards" / self.name

    @property
    def linux(self) -> dict[str, Any]:
        lx = self.data["linux"]
        assert isinstance(lx, dict)
        return lx

    @property
    def servo(self) -> dict[str, Any]:
        sv = self.data.get("servo", {})
        assert isinstance(sv, dict)
        return sv

    @property
    def arch(self) -> str:
        """Linux's architecture in the kernel's terms: ``arm`` (the
        Zynq-7000's A9, the default) or ``arm64`` (the ZynqMP's A53)."""
        return str(self.linux.get("arch", "arm"))

    @property
    def modules(self) -> list[str]:
        """The out-of-tree kernel modules the board's initramfs gets
        (linux.modules: folders of linux/, e.g. ``uio``; none when absent)."""
        return [str(m) for m in self.linux.get("modules") or []]

    @property
    def boot_flow(self) -> str:
        """How the board starts (board.yaml: qemu: boot): ``stub`` (the Zynq-7000: every
        CPU in the boot stub, which enters the zImage; the default) or
        ``tf-a`` (the ZynqMP: CPU0 in TF-A's BL31, which enters BL33)."""
        return str(self.qemu.get("boot", "stub"))

    def dts(self, variant: str | None = None) -> Path:
        """The Linux devicetree source of ``variant`` (linux.variants; None:
        $SERVOAMP_DTS, else the board's linux.variant, else linux.dts;
        ``default`` names linux.dts itself)."""
        variants = self.linux.get("variants") or {}
        if variant is None and variants:
            variant = os.environ.get("SERVOAMP_DTS") or self.linux.get("variant")
        if variant in (None, "default"):
            return self.folder / str(self.linux["dts"])
        if variant not in variants:
            raise QemuError(f"board {self.name}: no devicetree variant {variant!r} "
                            f"(have: default, {', '.join(variants)})")
        return self.folder / str(variants[variant])


def rproc_words(header: Path = REPO / "include" / "servoamp" / "rproc_words.h") -> dict[str, int]:
    """The start/stop contract's words and offsets (``ZSR_CTRL_STOP``,
    ``ZSR_STATUS_RUNNING``, ...) as the driver and the firmware compile
    them: read from their one definition, include/servoamp/rproc_words.h."""
    words = {m.group(1): int(m.group(2), 0)
             for m in re.finditer(r"^#define\s+(ZSR_\w+)\s+(0x[0-9a-fA-F]+|\d+)\b", header.read_text(), re.M)}
    if not words:
        raise QemuError(f"{header}: no ZSR_ words")
    return words
