"""servoamp's Linux side on the ZynqMP's A53 (issue 35, item 3): servod,
ampctl and the telemetry transport built for the board's architecture
(board.yaml linux.arch: arm64, a row of scripts/mk/guest-arch.mk) with
-Werror, the cycle interrupt's UIO driver built against the board's Linux
6.12 arm64 PREEMPT_RT kernel without warnings and checkpatch-clean, and
all of them in the board's initramfs beside the R5 test firmware. The
board test boots the ZynqMP once and runs them on the A53.

The userland build is checked for both boards (one row each), so the
per-architecture table is exercised both ways."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path
from typing import Literal

import pytest

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "python"))

from servoamp import qemu  # noqa: E402

# what `file` would say, per Linux architecture (Board.arch): ELF class
# (1: 32-bit, 2: 64-bit), e_machine (EM_ARM 40, EM_AARCH64 183) and
# `uname -m` on the target
ELF = {"arm": (1, 40), "arm64": (2, 183)}
UNAME_M = {"arm": "armv7l", "arm64": "aarch64"}
# the one link-time note of a static glibc program that resolves names
# (telem.c's getaddrinfo; the same on armhf): not a compiler warning
STATIC_GETADDRINFO = "Using 'getaddrinfo' in statically linked applications"
TAINT_OOT_MODULE = 1 << 12      # "O": every out-of-tree module sets it
PT_INTERP = 3


def elf_header(path: Path) -> tuple[int, int, int, bool]:
    """(ELF class, e_type, e_machine, has a PT_INTERP: dynamically linked)."""
    data = path.read_bytes()
    assert data[:4] == b"\x7fELF", f"{path}: not an ELF file"
    cls = data[4]
    order: Literal["little", "big"] = "little" if data[5] == 1 else "big"

    def word(off: int, size: int) -> int:
        return int.from_bytes(data[off:off + size], order)

    e_type, machine = word(16, 2), word(18, 2)
    if cls == 2:
        phoff, phentsize, phnum = word(0x20, 8), word(0x36, 2), word(0x38, 2)
    else:
        phoff, phentsize, phnum = word(0x1C, 4), word(0x2A, 2), word(0x2C, 2)
    interp = any(word(phoff + i * phentsize, 4) == PT_INTERP for i in range(phnum))
    return cls, e_type, machine, interp


def assert_static_program(path: Path, board: qemu.Board) -> None:
    cls, e_type, machine, interp = elf_header(path)
    assert (cls, machine) == ELF[board.arch], f"{path}: ELF class {cls}, machine {machine}"
    assert e_type == 2 and not interp, f"{path}: not a static executable"


def warnings_in(output: str) -> list[str]:
    return [ln for ln in output.splitlines()
            if "warning" in ln.lower() and STATIC_GETADDRINFO not in ln]


def make(*args: str | Path) -> str:
    res = subprocess.run(["nice", "-n", "10", "make", *map(str, args)], cwd=REPO, capture_output=True, text=True,
                         timeout=600)
    out = res.stdout + res.stderr
    assert res.returncode == 0, out[-4000:]
    return out


@pytest.fixture(scope="module")
def board() -> qemu.Board:
    return qemu.Board.load("zynqmp_qemu")


@pytest.fixture(scope="module")
def kdir(board: qemu.Board) -> Path:
    """The board's kernel build (linux/kernel/build-zynqmp.sh, cached)."""
    return qemu.board_kernel_dir(board)


@pytest.mark.parametrize("board_name", ["zynq7000_qemu", "zynqmp_qemu"])
def test_userland_builds_for_the_board_arch_with_werror(board_name: str, tmp_path: Path) -> None:
    """servod, ampctl, libmotion.a and the telemetry transport for the
    architecture board.yaml names, every compile with -Werror and no
    warning; the programs are static ELF files of that architecture."""
    b = qemu.Board.load(board_name)
    arch = qemu.guest_arch(b)
    assert arch == {"arm": "armhf", "arm64": "arm64"}[b.arch]
    out = make("-C", "motion", "-j2", "cross", f"GUEST_ARCH={arch}", f"BUILD={tmp_path / 'motion'}")
    assert (tmp_path / "motion" / arch / "libmotion.a").is_file(), out[-2000:]
    out += make("-B", "-C", "linux/telemetry", "cross", f"GUEST_ARCH={arch}")
    telem = REPO / "build" / "telemetry" / arch / "telem.o"
    assert elf_header(telem)[::2] == ELF[b.arch]
    out += make("-C", "linux/servod", "-j2", f"GUEST_ARCH={arch}", f"BUILD={tmp_path / 'servod'}")
    compiles = [ln for ln in out.splitlines() if re.match(r"\S*-gcc ", ln)]
    assert len(compiles) > 10 and all("-Werror" in ln for ln in compiles), compiles
    assert warnings_in(out) == []
    for prog in ("servod", "ampctl"):
        assert_static_program(tmp_path / "servod" / prog, b)


def test_board_modules_are_data(board: qemu.Board) -> None:
    """The ZynqMP's initramfs gets the cycle interrupt's UIO driver and not
    the Zynq-7000's remoteproc driver (the R5s have the upstream one): a
    list in each board.yaml, not a test of the board's name."""
    assert board.modules == ["uio"]
    assert qemu.Board.load("zynq7000_qemu").modules == ["remoteproc", "uio"]
    with pytest.raises(qemu.QemuError):
        qemu.build_modules(Path("/nonexistent"), ["no-such-driver"])


def test_uio_module_builds_against_the_board_kernel(board: qemu.Board, kdir: Path, tmp_path: Path) -> None:
    """servoamp_cycle_uio.ko against the 6.12 arm64 PREEMPT_RT build tree
    (linux/kmod.mk takes ARCH and the compiler from the kernel's info):
    no warning (W=0 is -Werror for modules), an AArch64 module whose
    vermagic is the board kernel's release with preempt_rt."""
    for folder in board.modules:
        build = tmp_path / folder
        out = make("-C", f"linux/{folder}", f"KDIR={kdir / 'obj'}", f"BUILD={build}")
        assert "ARCH=arm64" in out and "CROSS_COMPILE=aarch64-linux-gnu-" in out, out
        assert warnings_in(out) == [], out
        ko = build / qemu.KERNEL_MODULES[folder]
        cls, e_type, machine, _ = elf_header(ko)
        assert (cls, machine) == ELF[board.arch] and e_type == 1     # ET_REL
        release = next(ln[len("kernelrelease="):] for ln in (kdir / "info").read_text().splitlines()
                       if ln.startswith("kernelrelease="))
        vermagic = re.search(rb"vermagic=([^\0]+)", ko.read_bytes())
        assert vermagic, f"{ko}: no vermagic"
        assert vermagic.group(1).decode().split()[0] == release
        assert "preempt_rt" in vermagic.group(1).decode()


def test_uio_module_checkpatch_clean_on_the_board_kernel(board: qemu.Board, kdir: Path) -> None:
    """The 6.12 tree's scripts/checkpatch.pl --strict on the board's module
    sources (make checkpatch: linux/kmod.mk)."""
    for folder in board.modules:
        out = make("-C", f"linux/{folder}", f"KDIR={kdir / 'obj'}", "checkpatch")
        assert str(qemu.kernel_source(kdir)) in out
        totals = re.findall(r"^total: .*$", out, re.M)
        assert totals and all(t.startswith("total: 0 errors, 0 warnings, 0 checks") for t in totals), out


def test_initramfs_has_the_arm64_userland_and_module(board: qemu.Board) -> None:
    """prepare_images (build_initramfs, arch arm64) puts servod and ampctl
    (the arm64 build) in /usr/bin, as on the Zynq-7000, the UIO module in
    /lib/modules, and keeps the R5 test firmware in /lib/firmware."""
    imgs = qemu.prepare_images(board)
    listing = (imgs.initramfs.parent / "list").read_text().splitlines()
    files = {f[1]: Path(f[2]) for f in (ln.split() for ln in listing) if f[0] == "file"}
    for prog in ("servod", "ampctl"):
        assert_static_program(files[f"/usr/bin/{prog}"], board)
    assert {p for p in files if p.startswith("/usr/bin/")} == {f"/usr/bin/{p.name}" for p in qemu.build_userland()}
    assert sorted(p for p in files if p.startswith("/lib/modules/")) == ["/lib/modules/servoamp_cycle_uio.ko"]
    assert elf_header(files["/lib/modules/servoamp_cycle_uio.ko"])[::2] == ELF[board.arch]
    default = board.servo["default_firmware"]
    assert f"/lib/firmware/{default['name']}" in files and f"/lib/firmware/{default['image']}" in files
    assert {f"/lib/firmware/{p.name}" for p in imgs.firmware} <= set(files)


@pytest.mark.board
def test_servod_ampctl_and_the_uio_module_on_the_a53(board: qemu.Board) -> None:
    """One boot on virtual time: servod and ampctl run on the A53 (servod
    opens the OCM mailbox and the cycle interrupt through UIO and waits for
    the servo; ampctl asks it; the exchange with the R5:
    tests/robot/zynqmp/05_cycle.robot); /init loaded the UIO module (only
    the out-of-tree taint) and gave the cycle interrupt's thread its
    priority; rmmod and insmod again with nothing in dmesg; irqprio sets an
    interrupt thread's SCHED_FIFO priority on the mainline PREEMPT_RT
    kernel."""
    imgs = qemu.prepare_images(board)
    prompt = str(board.data["linux"]["prompt"])
    with qemu.QemuMachine(board, imgs, clock="virtual") as m:
        qemu.boot_to_shell(m, timeout=300)
        console = m.uart(0)

        def sh(cmd: str) -> tuple[int, str]:
            return qemu.run_shell(console, cmd, prompt, timeout=60)

        assert sh("uname -m") == (0, UNAME_M[board.arch])
        rc, out = sh("servod -h")
        assert rc == 1 and out.startswith("usage: servod"), out
        rc, out = sh("(servod --telemetry off -s /tmp/servod.sock -p /tmp/servod.params > /tmp/servod.log 2>&1 &); "
                     "i=0; until grep -q 'waiting for the servo' /tmp/servod.log || [ $i -ge 100 ]; do "
                     "sleep 0.05; i=$((i+1)); done; cat /tmp/servod.log")
        assert rc == 0, out
        assert "no parameter file /tmp/servod.params: defaults" in out, out
        assert "ocm-mailbox: /dev/uio" in out and "cycle-interrupt: /dev/uio" in out, out
        assert "waiting for the servo" in out, out
        rc, out = sh("ampctl -h")
        assert rc == 1 and out.startswith("usage: ampctl"), out
        rc, out = sh("ampctl -s /tmp/servod.sock status")
        assert rc == 3 and "remoteproc=offline" in out and "servo not running" in out, out
        assert sh("kill $(pidof servod); sleep 0.2; pidof servod")[0] == 1
        rc, out = sh("ampctl -s /tmp/servod.sock status")
        assert rc == 2 and "servod not reachable" in out, out

        # /init loaded the module, which bound the cycle interrupt, and gave
        # its thread FIFO 81
        boot_log = console.output
        assert "servoamp: no cycle interrupt in the devicetree" not in boot_log
        assert "servoamp: insmod" not in boot_log and "irqprio cycle-interrupt failed" not in boot_log
        rc, out = sh("grep ^servoamp_cycle_uio /proc/modules")
        assert rc == 0 and out.endswith("(O)"), out
        rc, out = sh("dmesg | grep -i -e cycle.uio -e taint")
        lines = out.splitlines()
        taint_note = "servoamp_cycle_uio: loading out-of-tree module taints kernel."
        bound = "servoamp-cycle-uio 80000058.cycle-interrupt: cycle interrupt"
        assert len(lines) == 2 and lines[0].endswith(taint_note) and bound in lines[1], out
        assert sh("cat /proc/sys/kernel/tainted") == (0, str(TAINT_OOT_MODULE))

        drv = "/sys/bus/platform/drivers/servoamp-cycle-uio"
        assert sh(f"dmesg -c >/dev/null; rmmod servoamp_cycle_uio && ! test -e {drv}")[0] == 0
        assert sh("grep -c ^servoamp_cycle_uio /proc/modules")[1] == "0"
        assert sh(f"insmod /lib/modules/servoamp_cycle_uio.ko && test -e {drv}")[0] == 0
        assert sh("grep -c ^servoamp_cycle_uio /proc/modules")[1] == "1"
        rc, out = sh("dmesg")
        # the driver binding the cycle interrupt again, and nothing else
        assert len(out.splitlines()) == 1 and bound in out, f"kernel messages after rmmod/insmod:\n{out}"
        assert sh("cat /proc/sys/kernel/tainted") == (0, str(TAINT_OOT_MODULE))
        assert sh("rmmod servoamp_cycle_uio && insmod /lib/modules/servoamp_cycle_uio.ko")[0] == 0

        # interrupt threads as on the Zynq-7000's 6.1-rt: irq/NN-NAME at
        # SCHED_FIFO 50, which irqprio (the initramfs', arm64) changes
        rc, irq = sh("sed -n 's/^ *\\([0-9]*\\):.* xuartps$/\\1/p' /proc/interrupts")
        assert rc == 0 and irq.isdigit(), irq
        pid = sh(f"for p in /proc/[0-9]*; do grep -qx 'irq/{irq}-xuartps' $p/comm && echo ${{p#/proc/}}; done")[1]
        assert pid.isdigit(), pid
        policy = f"awk '{{print $40, $41}}' /proc/{pid}/stat"      # rt_priority, policy (1: SCHED_FIFO)
        assert sh(policy)[1] == "50 1"
        rc, out = sh("irqprio xuartps 51")
        assert rc == 0 and "SCHED_FIFO 51" in out, out
        assert sh(policy)[1] == "51 1"
        assert sh("irqprio xuartps 50")[0] == 0
