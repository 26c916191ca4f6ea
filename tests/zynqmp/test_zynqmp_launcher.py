"""The launcher on the ZynqMP board without booting: the QEMU command line
comes from boards/zynqmp_qemu/board.yaml (nothing ZynqMP-specific in the
launcher's code), and servoamp.qemu still offers every name it had before
it was split by concern."""

from __future__ import annotations

import re
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "python"))

from servoamp import qemu  # noqa: E402

LAUNCHER = ["qemu.py", "board.py", "images.py", "runner.py", "uart.py", "qmp.py", "vcpu.py"]


def fake_images(board: qemu.Board) -> qemu.Images:
    return qemu.Images(stub=Path("/i/bl33.bin"), zimage=Path("/i/Image"), dtb=Path("/i/linux.dtb"),
                       initramfs=Path("/i/initramfs.cpio.gz"), bl31=Path("/i/bl31.bin"))


def test_command_line_from_board_yaml() -> None:
    board = qemu.Board.load("zynqmp_qemu")
    args = qemu.qemu_args(board, fake_images(board), ["chardev:uart0", "chardev:uart1"], clock="virtual")
    q = board.qemu
    assert args[args.index("-M") + 1] == f"{q['machine']},{q['machine_opts']}"
    assert args[args.index("-smp") + 1] == str(q["smp"]) and args[args.index("-m") + 1] == q["memory"]
    assert args[args.index("-icount") + 1] == q["clock"]["icount"]
    loaders = [args[i + 1] for i, a in enumerate(args) if a == "-device"]
    load = board.data["load"]
    assert loaders == [
        f"loader,file=/i/bl31.bin,addr={load['tf_a']:#x},force-raw=on",
        f"loader,file=/i/bl33.bin,addr={load['bl33']:#x},force-raw=on",
        f"loader,file=/i/Image,addr={load['image']:#x},force-raw=on",
        f"loader,file=/i/linux.dtb,addr={load['dtb']:#x},force-raw=on",
        f"loader,file=/i/initramfs.cpio.gz,addr={load['initramfs']:#x},force-raw=on",
        # only CPU0 starts, in BL31; the others stay off until PSCI/RPU control
        f"loader,addr={load['tf_a']:#x},cpu-num=0",
    ]
    assert [args[i + 1] for i, a in enumerate(args) if a == "-serial"] == ["chardev:uart0", "chardev:uart1"]


def test_dts_variants() -> None:
    board = qemu.Board.load("zynqmp_qemu")
    assert board.dts("default").name == "linux.dts"
    assert board.dts("no-pmu").name == "linux-nopmu.dts"
    assert board.dts().name == "linux.dts"      # the board's own unless board.yaml names a variant
    assert qemu.Board.load("zynq7000_qemu").dts().name == "linux.dts"


def test_no_board_numbers_in_the_launcher() -> None:
    """The launcher takes the ZynqMP's numbers from board.yaml: no machine
    name, no address of that board in its code."""
    board = qemu.Board.load("zynqmp_qemu")
    numbers = {v for section in ("load", "tf_a", "ddr", "ocm", "gic") for v in board.data[section].values()
               if isinstance(v, int) and v > 0x10000}
    for name in LAUNCHER:
        text = (REPO / "python/servoamp" / name).read_text()
        assert "zcu102" not in text and "zynqmp_qemu" not in text, name
        found = {int(h, 16) for h in re.findall(r"\b0x([0-9a-fA-F]+)\b", text)}
        assert not found & numbers, (name, sorted(hex(n) for n in found & numbers))


def test_facade_keeps_every_name() -> None:
    """What the callers use (python/, tests/, bench/, scripts/) is still in
    servoamp.qemu."""
    used: set[str] = set()
    for folder in ("python", "tests", "bench", "scripts"):
        for f in (REPO / folder).rglob("*.py"):
            used |= set(re.findall(r"(?<![\w.])qemu\.([A-Za-z_][A-Za-z0-9_]*)", f.read_text(errors="replace")))
    for name in sorted(used):
        if name in ("stderr", "log", "clock", "uarts", "py"):   # other objects named qemu, file names
            continue
        assert hasattr(qemu, name), name
