"""Launch the emulated servoamp board in QEMU and talk to it.

The board's numbers come from ``boards/<board>/board.yaml`` (load addresses,
memory map, QEMU machine). This module

* builds what the launch needs and is cheap (boot stub, DTB with the
  initramfs location in /chosen) and, through :func:`prepare_images`, runs
  the cached build scripts for the rest (kernel, remoteproc module, test
  firmware, initramfs);
* starts QEMU with both CPUs pointed at the boot stub (``-device loader``;
  ``-kernel`` cannot boot this two-core machine), each UART connected to a
  TCP socket on 127.0.0.1 that this process listens on (QEMU connects as
  the client, so no port is ever guessed) and QMP on a unix socket;
* offers :class:`Uart` (wait for a line or a prompt, write a line) and
  :meth:`QemuMachine.hmp` / :meth:`QemuMachine.read_word` (monitor commands
  such as ``xp /1wx 0xffff8004``), with timeouts everywhere;
* shuts QEMU down cleanly (QMP ``quit``, then SIGTERM, then SIGKILL) and
  keeps the run directory (UART logs, QEMU stderr, command line) when
  something failed.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import socket
import subprocess
import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml  # type: ignore[import-untyped]

REPO = Path(__file__).resolve().parents[2]
ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]|\x1b[()][A-Za-z0-9]")


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


def rproc_words(header: Path = REPO / "include" / "servoamp" / "rproc_words.h") -> dict[str, int]:
    """The start/stop contract's words and offsets (``ZSR_CTRL_STOP``,
    ``ZSR_STATUS_RUNNING``, ...) as the driver and the firmware compile
    them: read from their one definition, include/servoamp/rproc_words.h."""
    words = {m.group(1): int(m.group(2), 0)
             for m in re.finditer(r"^#define\s+(ZSR_\w+)\s+(0x[0-9a-fA-F]+|\d+)\b", header.read_text(), re.M)}
    if not words:
        raise QemuError(f"{header}: no ZSR_ words")
    return words


# --------------------------------------------------------------------------
# Images
# --------------------------------------------------------------------------


@dataclass(frozen=True)
class Images:
    """Everything QEMU loads."""

    stub: Path
    zimage: Path
    dtb: Path
    initramfs: Path
    firmware: tuple[Path, ...] = ()
    stub_icount: Path | None = None   # park loop in wfi + private timer, for -icount (stub.S)


def _run(cmd: Sequence[str | Path], **kw: Any) -> subprocess.CompletedProcess[str]:
    res = subprocess.run([str(c) for c in cmd], text=True, capture_output=True, **kw)
    if res.returncode != 0:
        raise QemuError(
            f"command failed ({res.returncode}): {' '.join(map(str, cmd))}\n"
            f"{res.stdout[-3000:]}{res.stderr[-3000:]}"
        )
    return res


KERNELS = ("rt", "vanilla")


def default_kernel() -> str:
    """The kernel variant the board boots: ``rt`` (PREEMPT_RT, the
    default: issue 23's latency table, docs/cycle.md) or ``vanilla`` (the
    non-preemptible 6.1), from $SERVOAMP_KERNEL (``west emu --kernel`` sets
    it); linux/kernel/build.sh --variant builds either."""
    kernel = os.environ.get("SERVOAMP_KERNEL") or "rt"
    if kernel not in KERNELS:
        raise QemuError(f"SERVOAMP_KERNEL={kernel}: expected one of {', '.join(KERNELS)}")
    return kernel


def kernel_link(kernel: str | None = None) -> Path:
    """``build/kernel-rt`` or ``build/kernel`` (vanilla): the link to the
    variant's cached build (linux/kernel/build.sh)."""
    kernel = kernel or default_kernel()
    return REPO / "build" / ("kernel" if kernel == "vanilla" else f"kernel-{kernel}")


def kernel_dir(kernel: str | None = None) -> Path:
    """The kernel build of variant ``kernel`` (default:
    :func:`default_kernel`; ``build/kernel-rt`` or ``build/kernel`` -> cache), built if
    missing."""
    kernel = kernel or default_kernel()
    link = kernel_link(kernel)
    if not (link / "ok").exists():
        subprocess.run([REPO / "linux/kernel/build.sh", "--variant", kernel], check=True)
    return link.resolve()


def kernel_source(kdir: Path) -> Path:
    for line in (kdir / "info").read_text().splitlines():
        if line.startswith("src="):
            return Path(line[4:])
    raise QemuError(f"{kdir}/info has no src=")


def build_stub(board: Board, park_wfe: bool = True) -> Path:
    """Assemble the boot stub with the board's addresses: ``stub.bin``
    (CPU1 parks in wfe, for the host clock) or, with ``park_wfe=False``,
    ``stub-icount.bin`` (CPU1 waits in wfi, woken by its private timer, for
    virtual time; see stub.S)."""
    out = board.build_dir
    park = board.addr("load", "park_loop") - board.addr("load", "boot_stub")
    name = "stub" if park_wfe else "stub-icount"
    _run(
        [
            "make", "-s", "-C", board.folder / "boot", f"OUT={out}", f"STUB={name}",
            f"PARK_WFE={int(park_wfe)}",
            f"STUB_ADDR={board.addr('load', 'boot_stub'):#x}",
            f"ZIMAGE_ADDR={board.addr('load', 'zimage'):#x}",
            f"DTB_ADDR={board.addr('load', 'dtb'):#x}",
            f"ARM_PLL_CTRL_VALUE={board.addr('slcr', 'arm_pll_ctrl'):#x}",
            f"PARK_OFFSET={park:#x}",
        ]
    )
    return out / f"{name}.bin"


def build_dtb(board: Board, ksrc: Path, initramfs: Path | None = None, out_dir: Path | None = None) -> Path:
    """cpp + dtc on the board's Linux DTS (warnings are errors), then put the
    initramfs location into /chosen. ``out_dir``: where linux.dtb goes
    (default: the board's build directory; a benchmark booting an initramfs
    of its own passes its own directory, so that the board's DTB, which
    other boots read, keeps its /chosen)."""
    out = out_dir or board.build_dir
    out.mkdir(parents=True, exist_ok=True)
    dts = board.folder / str(board.data["linux"]["dts"])
    pre = out / "linux.dts.pp"
    dtb = out / "linux.dtb"
    _run(
        [
            "cpp", "-nostdinc", "-undef", "-x", "assembler-with-cpp", "-D__DTS__",
            "-I", ksrc / "include", "-I", ksrc / "arch/arm/boot/dts",
            "-I", REPO / "devicetree", "-o", pre, dts,
        ]
    )
    res = _run(["dtc", "-I", "dts", "-O", "dtb", "-o", dtb, pre])
    if res.stderr.strip():
        raise QemuError(f"dtc warnings on {dts}:\n{res.stderr}")
    if initramfs is not None:
        start = board.addr("load", "initramfs")
        end = start + initramfs.stat().st_size
        _run(["fdtput", "-t", "x", dtb, "/chosen", "linux,initrd-start", f"{start:x}"])
        _run(["fdtput", "-t", "x", dtb, "/chosen", "linux,initrd-end", f"{end:x}"])
    return dtb


# The out-of-tree modules the board loads: linux/<folder>/ -> its module
KERNEL_MODULES = {"remoteproc": "zynq_servo_rproc.ko", "uio": "servoamp_cycle_uio.ko"}


def build_modules(kdir: Path) -> list[Path]:
    """The out-of-tree modules (linux/kmod.mk; about 1 s each): the
    remoteproc driver and the cycle interrupt's UIO driver."""
    key = next(l[4:] for l in (kdir / "info").read_text().splitlines() if l.startswith("key="))
    out = []
    for folder, ko in KERNEL_MODULES.items():
        build = REPO / "build/linux" / folder / key
        _run(["make", "-s", "-C", REPO / "linux" / folder, f"KDIR={kdir / 'obj'}", f"BUILD={build}"])
        out.append(build / ko)
    return out


def build_test_firmware() -> list[Path]:
    """The test firmware of tests/robot/fixtures (good and bad images)."""
    out = REPO / "build/tests/fixtures"
    _run(["make", "-s", "-C", REPO / "tests/robot/fixtures", f"OUT={out}"])
    return sorted(out.glob("*.elf"))


# rpu_app's outputs (rpu_app/Makefile) and the names they get in the guest's
# /lib/firmware: "rpu_app*.elf" names the firmware, where "servo.elf" would not.
RPU_APP_IMAGES = {"servo.elf": "rpu_app.elf", "servo-norsc.elf": "rpu_app-norsc.elf"}
# rpu_app's builds for one board: name suffix -> the servo devicetree in
# boards/<board>/ ("": the board's own axes; "-can": its axes on CiA 402
# drives over CAN, staged as rpu_app-can.elf, built when the board has one)
RPU_APP_VARIANTS = {"": "servo.dts", "-can": "servo-can.dts"}


def rpu_app_firmware(board: Board, build: bool = True) -> list[Path]:
    """rpu_app's ELFs for ``board``, built with rpu_app's Makefile when it
    has one, staged under their /lib/firmware names. Empty when rpu_app
    has not been written yet."""
    mk = REPO / "rpu_app" / "Makefile"
    stage = REPO / "build" / "firmware" / board.name
    found = []
    for variant, dts in RPU_APP_VARIANTS.items():
        dts_path = REPO / "boards" / board.name / dts
        src_dir = REPO / "build" / "rpu_app" / (board.name + variant)
        if not dts_path.exists():
            continue
        if build and mk.exists():
            _run(["make", "-s", "-C", REPO / "rpu_app", "-j2", f"BOARD={board.name}",
                  f"DTS={dts_path}", f"BUILD={src_dir}"])
        for src, name in RPU_APP_IMAGES.items():
            if variant and src != "servo.elf":
                continue        # a variant's image with its resource table only
            if (src_dir / src).exists():
                staged = stage / name.replace("rpu_app", "rpu_app" + variant, 1)
                stage.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(src_dir / src, staged)
                found.append(staged)
    return found


def build_userland() -> list[Path]:
    """servod and ampctl (linux/servod, static armhf), when their sources exist."""
    mk = REPO / "linux" / "servod" / "Makefile"
    if not mk.exists():
        return []
    out = REPO / "build" / "linux" / "servod"
    _run(["make", "-s", "-C", mk.parent, f"BUILD={out}"])
    return [out / "servod", out / "ampctl"]


def build_initramfs(modules: Sequence[Path], firmware: Sequence[Path], bins: Sequence[Path] = ()) -> Path:
    cmd: list[str | Path] = [REPO / "linux/initramfs/build.sh", "--print"]
    for m in modules:
        cmd += ["--module", m]
    for f in firmware:
        cmd += ["--firmware", f]
    for b in bins:
        cmd += ["--bin", b]
    res = subprocess.run([str(c) for c in cmd], text=True, stdout=subprocess.PIPE, check=True)
    return Path(res.stdout.strip().splitlines()[-1])


def prepare_images(
    board: Board, firmware: Sequence[Path] | None = None, with_rpu_app: bool = True
) -> Images:
    """Build (or take from the caches) every image of a boot.

    ``firmware``: ELF files for /lib/firmware; default: the test fixtures
    plus rpu_app's ELF(s) when they exist.
    """
    kdir = kernel_dir()
    modules = build_modules(kdir)
    if firmware is None:
        firmware = build_test_firmware()
        if with_rpu_app:
            firmware = list(firmware) + rpu_app_firmware(board)
    initramfs = build_initramfs(modules, firmware, build_userland())
    stub = build_stub(board)
    stub_icount = build_stub(board, park_wfe=False)
    dtb = build_dtb(board, kernel_source(kdir), initramfs)
    return Images(
        stub=stub, zimage=kdir / "zImage", dtb=dtb, initramfs=initramfs, firmware=tuple(firmware),
        stub_icount=stub_icount,
    )


# --------------------------------------------------------------------------
# QEMU command line
# --------------------------------------------------------------------------


_QEMU_DIR: Path | None = None


def project_qemu() -> Path:
    """The project's own QEMU (emulator/qemu/build.sh: Debian's source with
    our patches, cached by its inputs; built on first use), as the folder
    that holds ``bin/``; looked up once per process."""
    global _QEMU_DIR
    if _QEMU_DIR is None:
        res = subprocess.run([str(REPO / "emulator/qemu/build.sh"), "--print"], text=True,
                             stdout=subprocess.PIPE)
        if res.returncode != 0:
            raise QemuError("emulator/qemu/build.sh failed (its log is named above)")
        _QEMU_DIR = Path(res.stdout.strip().splitlines()[-1])
    return _QEMU_DIR


def check_qemu(board: Board) -> str:
    """Path of the QEMU binary: $SERVOAMP_QEMU when set, else the project's
    own build (:func:`project_qemu`); refuses versions older than the board
    needs."""
    name = str(board.qemu["binary"])
    binary = os.environ.get("SERVOAMP_QEMU") or str(project_qemu() / "bin" / name)
    if not os.access(binary, os.X_OK):
        raise QemuError(f"{binary}: not an executable QEMU")
    out = _run([binary, "--version"]).stdout
    m = re.search(r"version (\d+)\.(\d+)", out)
    want = tuple(int(x) for x in str(board.qemu["min_version"]).split("."))
    if not m or (int(m.group(1)), int(m.group(2))) < want:
        raise QemuError(f"{binary}: QEMU >= {board.qemu['min_version']} needed, got: {out.splitlines()[0]}")
    return binary


CLOCKS = ("virtual", "host")


def default_clock() -> str:
    """``virtual`` (the default: instruction-counted guest time, -icount) or
    ``host`` ($SERVOAMP_CLOCK=host: guest time follows the host clock).

    Under virtual time host load cannot make the guest miss a cycle: it only
    changes how long a guest second takes on the host (docs/cycle.md,
    section 6). The host clock stays for interactive use, where the guest
    should keep pace with a person."""
    clock = os.environ.get("SERVOAMP_CLOCK", "virtual")
    if clock not in CLOCKS:
        raise QemuError(f"SERVOAMP_CLOCK={clock!r}: expected one of {', '.join(CLOCKS)}")
    return clock


def clock_args(board: Board, clock: str | None = None, icount: str | None = None) -> list[str]:
    """QEMU's time-base arguments. ``virtual``: ``-icount`` with the board's
    spec (board.yaml qemu.clock; ``icount`` overrides it) and the RTC on
    virtual time, so guest time advances with the instructions executed and
    host load cannot make the guest miss a cycle. ``host``: none (QEMU's
    default, guest time = host time)."""
    clock = clock or default_clock()
    if clock not in CLOCKS:
        raise QemuError(f"clock {clock!r}: expected one of {', '.join(CLOCKS)}")
    if clock == "host":
        return []
    c = board.qemu["clock"]
    return ["-icount", icount or str(c["icount"]), "-rtc", str(c["rtc"])]


CAN_BUSES = (0, 1)                    # the Zynq-7000's CAN0 and CAN1
CAN_LINK_OPTS = ("bitrate", "timeout-ms", "max-timeouts")


def can_args(can_links: Mapping[int, str | Path] | None,
             can_link_opts: Mapping[str, int] | None = None) -> tuple[str, list[str]]:
    """The CAN buses linked to host processes by canlink (docs/canlink.md):
    ``can_links`` maps a controller (0: CAN0, 1: CAN1) to the Unix socket
    path its bus's ``can-host-lockstep`` backend listens on;
    ``can_link_opts`` sets the backend's ``bitrate``, ``timeout-ms`` and
    ``max-timeouts`` (the backend's defaults otherwise). Returns the machine
    properties to append to ``-M`` (``,canbus0=canbus0``) and the
    ``-object`` arguments."""
    if not can_links:
        return "", []
    opts = dict(can_link_opts or {})
    for k, v in opts.items():
        if k not in CAN_LINK_OPTS:
            raise QemuError(f"can-host-lockstep option {k!r}: expected one of {', '.join(CAN_LINK_OPTS)}")
        if isinstance(v, bool) or not isinstance(v, int) or v <= 0:
            raise QemuError(f"can-host-lockstep option {k}={v!r}: expected a positive integer")
    machine = ""
    objects: list[str] = []
    for bus, path in sorted(can_links.items()):
        if bus not in CAN_BUSES:
            raise QemuError(f"CAN bus {bus!r}: the board has CAN0 and CAN1 (0, 1)")
        p = str(path)
        if not p or "," in p or len(os.fsencode(p)) >= 108:
            raise QemuError(f"canlink socket path {p!r}: empty, with a comma, or too long for a Unix socket")
        machine += f",canbus{bus}=canbus{bus}"
        link = f"can-host-lockstep,id=canlink{bus},canbus=canbus{bus},path={p}"
        link += "".join(f",{k}={v}" for k, v in opts.items())
        objects += ["-object", f"can-bus,id=canbus{bus}", "-object", link]
    return machine, objects


def machine_args(board: Board, serials: Sequence[str], accel: str | None = None, clock: str | None = None,
                 icount: str | None = None, can_links: Mapping[int, str | Path] | None = None,
                 can_link_opts: Mapping[str, int] | None = None) -> list[str]:
    """The machine of ``board`` without any image: machine, CPUs, memory,
    accelerator, time base (:func:`clock_args`), one ``-serial`` value
    per UART of ``serials``, in board order, and the CAN buses linked to
    host processes (:func:`can_args`). Every run of the board starts
    from these: the Linux boot (:func:`qemu_args`) and the firmware alone
    (tests/rpu_app, its loaders in :attr:`QemuMachine.extra_args`)."""
    q = board.qemu
    can_machine, can_objects = can_args(can_links, can_link_opts)
    args = [
        "-M", str(q["machine"]) + can_machine, "-smp", str(q["smp"]), "-m", str(q["memory"]),
        "-display", "none", "-nodefaults",
    ]
    timebase = clock_args(board, clock, icount)
    if timebase and accel and "thread=multi" in accel:
        raise QemuError("virtual time (-icount) needs single-threaded TCG; use the host clock for thread=multi")
    if accel:
        args += ["-accel", accel]
    args += timebase
    for s in serials:
        args += ["-serial", s]
    return args + can_objects


def qemu_args(board: Board, images: Images, serials: Sequence[str], accel: str | None = None,
              clock: str | None = None, icount: str | None = None,
              can_links: Mapping[int, str | Path] | None = None,
              can_link_opts: Mapping[str, int] | None = None) -> list[str]:
    """The QEMU arguments (without the binary) for a boot of ``board``.

    ``serials``: one ``-serial`` value per UART, in board order; ``clock``
    and ``icount``: see :func:`clock_args`; ``can_links`` and
    ``can_link_opts``: see :func:`can_args`.
    """
    q = board.qemu
    stub = board.addr("load", "boot_stub")
    args = machine_args(board, serials, accel, clock, icount, can_links, can_link_opts)
    timebase = clock_args(board, clock, icount)
    if timebase and images.stub_icount is None:
        raise QemuError("virtual time needs the boot stub without wfe (prepare_images builds it)")
    loads = [
        (images.stub_icount if timebase else images.stub, stub),
        (images.zimage, board.addr("load", "zimage")),
        (images.dtb, board.addr("load", "dtb")),
        (images.initramfs, board.addr("load", "initramfs")),
    ]
    for f, a in loads:
        args += ["-device", f"loader,file={f},addr={a:#x},force-raw=on"]
    for cpu in range(int(q["smp"])):
        args += ["-device", f"loader,addr={stub:#x},cpu-num={cpu}"]
    return args


# --------------------------------------------------------------------------
# UART
# --------------------------------------------------------------------------


class Uart:
    """One UART of the board, connected through a TCP socket.

    Everything received is appended to a log file and to a buffer; the
    waits search the buffer from a cursor and move it past what matched, as
    Renode's terminal tester does. ANSI escape sequences and CR are removed.
    """

    def __init__(self, name: str, sock: socket.socket, log_path: Path,
                 on_timeout: Callable[[str], object] | None = None) -> None:
        self.name = name
        #: called (outside the lock) when a wait times out, before the
        #: QemuError: QemuMachine dumps both vCPUs' state there
        self.on_timeout = on_timeout
        self._sock = sock
        self._log = log_path.open("wb")
        self._buf = ""
        self._pos = 0
        self._cond = threading.Condition()
        self._closed = False
        self._thread = threading.Thread(target=self._reader, name=f"uart-{name}", daemon=True)
        self._thread.start()

    def _reader(self) -> None:
        pending = b""
        while True:
            try:
                data = self._sock.recv(4096)
            except OSError:
                data = b""
            if not data:
                break
            self._log.write(data)
            self._log.flush()
            pending += data
            # keep an incomplete escape sequence for the next chunk
            cut = pending.rfind(b"\x1b")
            if cut >= 0 and len(pending) - cut < 8 and not re.search(rb"\x1b\[[0-9;?]*[A-Za-z]", pending[cut:]):
                text, pending = pending[:cut], pending[cut:]
            else:
                text, pending = pending, b""
            clean = ANSI.sub("", text.decode("utf-8", "replace")).replace("\r", "")
            with self._cond:
                self._buf += clean
                self._cond.notify_all()
        with self._cond:
            self._closed = True
            self._cond.notify_all()

    def _wait(self, find: Any, timeout: float, what: str) -> str:
        deadline = time.monotonic() + timeout
        with self._cond:
            while True:
                hit = find(self._buf, self._pos)
                if hit is not None:
                    start, end = hit
                    self._pos = end
                    return self._buf[start:end]
                left = deadline - time.monotonic()
                if left <= 0 or self._closed:
                    tail = self._buf[self._pos:][-800:]
                    closed = self._closed
                    break
                self._cond.wait(left)
        state = "closed" if closed else f"{timeout:g} s"
        extra = ""
        if not closed and self.on_timeout is not None:
            try:
                self.on_timeout(f"{self.name}: no {what} within {timeout:g} s")
            except Exception as e:  # the dump must never hide the timeout
                extra = f"\n(vCPU state dump failed: {e})"
        raise QemuError(f"{self.name}: no {what} ({state}); unread output:\n{tail}{extra}")

    def wait_for_line(self, text: str, timeout: float = 10.0, regex: bool = False) -> str:
        """Wait for a line that contains ``text`` (or matches the regex) and
        return that whole line (without the newline)."""
        pat = re.compile(text, re.M) if regex else re.compile(re.escape(text))

        def find(buf: str, pos: int) -> tuple[int, int] | None:
            m = pat.search(buf, pos)
            if not m:
                return None
            start = buf.rfind("\n", 0, m.start()) + 1
            end = buf.find("\n", m.end())
            if end < 0:
                return None  # the line is not complete yet
            return max(start, pos), end + 1

        return self._wait(find, timeout, f"line matching {text!r}").rstrip("\n")

    def wait_for_text(self, text: str, timeout: float = 10.0) -> str:
        """Wait for ``text`` anywhere (no newline needed); return everything
        from the cursor to the end of the match."""

        def find(buf: str, pos: int) -> tuple[int, int] | None:
            i = buf.find(text, pos)
            return None if i < 0 else (pos, i + len(text))

        return self._wait(find, timeout, f"text {text!r}")

    def write(self, data: str) -> None:
        self._sock.sendall(data.encode())

    def write_line(self, line: str) -> None:
        self.write(line + "\n")

    @property
    def cursor(self) -> int:
        """Index in :attr:`output` up to which the waits have consumed."""
        with self._cond:
            return self._pos

    def unread(self) -> str:
        with self._cond:
            return self._buf[self._pos:]

    def skip(self) -> None:
        """Forget everything received so far."""
        with self._cond:
            self._pos = len(self._buf)

    @property
    def output(self) -> str:
        with self._cond:
            return self._buf

    def close(self) -> None:
        try:
            self._sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self._sock.close()
        self._thread.join(timeout=2)
        self._log.close()


# --------------------------------------------------------------------------
# QMP
# --------------------------------------------------------------------------


def connect_unix(path: Path | str, timeout: float = 10.0, what: str = "socket") -> socket.socket:
    """Connect to a unix socket QEMU is still creating (QMP, gdbstub),
    retrying until ``timeout``; the socket then has that timeout."""
    deadline = time.monotonic() + timeout
    while True:
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            sock.connect(str(path))
            break
        except OSError:
            sock.close()
            if time.monotonic() > deadline:
                raise QemuError(f"{what} {path} did not come up") from None
            time.sleep(0.02)
    sock.settimeout(timeout)
    return sock


class Qmp:
    """A minimal QMP client (JSON lines over a unix socket)."""

    def __init__(self, path: Path, timeout: float = 60.0) -> None:
        # generous: QEMU greets from its main loop, which a host with more
        # busy processes than cores (seen: load 8 on 2 cores) can hold back
        # for over 10 s while the vCPU thread starts
        self._sock = connect_unix(path, timeout, "QMP socket")
        self._file = self._sock.makefile("rwb")
        self._read()  # greeting
        self.execute("qmp_capabilities")

    def _read(self) -> dict[str, Any]:
        while True:
            line = self._file.readline()
            if not line:
                raise QemuError("QMP connection closed")
            msg = json.loads(line)
            if "event" not in msg:
                assert isinstance(msg, dict)
                return msg

    def execute(self, cmd: str, **arguments: Any) -> Any:
        req: dict[str, Any] = {"execute": cmd}
        if arguments:
            req["arguments"] = arguments
        self._file.write(json.dumps(req).encode() + b"\n")
        self._file.flush()
        resp = self._read()
        if "error" in resp:
            raise QemuError(f"QMP {cmd}: {resp['error']}")
        return resp.get("return")

    def close(self) -> None:
        try:
            self._file.close()
            self._sock.close()
        except OSError:
            pass


# --------------------------------------------------------------------------
# The machine
# --------------------------------------------------------------------------


@dataclass
class QemuMachine:
    """One QEMU run of a board.

    >>> with QemuMachine(Board.load(), prepare_images(Board.load())) as m:
    ...     m.uart(0).wait_for_line("userspace ready", timeout=60)
    """

    board: Board
    images: Images | None             # None: no Linux boot, the loaders come in extra_args
    run_dir: Path | None = None
    accel: str | None = None
    extra_args: Sequence[str] = ()
    keep_logs: bool = False
    clock: str | None = None          # "virtual" (default_clock()) or "host": see clock_args()
    icount: str | None = None         # -icount spec instead of the board's
    can_links: Mapping[int, Path] | None = None   # CAN bus (0, 1) -> canlink socket: see can_args()
    can_link_opts: Mapping[str, int] | None = None
    uarts: list[Uart] = field(default_factory=list)
    _proc: subprocess.Popen[bytes] | None = None
    _qmp: Qmp | None = None
    _failed: bool = False
    started_at: float = 0.0

    def start(self, connect_timeout: float = 20.0) -> QemuMachine:
        binary = check_qemu(self.board)
        if self.run_dir is None:
            stamp = time.strftime("%Y%m%d-%H%M%S")
            self.run_dir = REPO / "build" / "qemu" / f"{self.board.name}-{stamp}-{os.getpid()}"
        self.run_dir.mkdir(parents=True, exist_ok=True)
        # QMP sockets live in a short path (unix socket names are limited)
        self._sockdir = Path(f"/tmp/servoamp-qmp-{os.getpid()}-{id(self):x}")
        self._sockdir.mkdir(exist_ok=True)
        qmp_path = self._sockdir / "qmp.sock"

        uart_defs = self.board.qemu["uarts"]
        listeners: list[socket.socket] = []
        serials: list[str] = []
        chardevs: list[str] = []
        for i, u in enumerate(uart_defs):
            ls = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            ls.bind(("127.0.0.1", 0))
            ls.listen(1)
            ls.settimeout(connect_timeout)
            listeners.append(ls)
            port = ls.getsockname()[1]
            chardevs += [
                "-chardev",
                f"socket,id=uart{i},host=127.0.0.1,port={port},server=off,nodelay=on",
            ]
            serials.append(f"chardev:uart{i}")
        if self.images is not None:
            args = chardevs + qemu_args(self.board, self.images, serials, self.accel, self.clock, self.icount,
                                        self.can_links, self.can_link_opts)
        else:
            args = chardevs + machine_args(self.board, serials, self.accel, self.clock, self.icount,
                                           self.can_links, self.can_link_opts)
        args += ["-qmp", f"unix:{qmp_path},server=on,wait=off"]
        args += list(self.extra_args)
        cmd = [binary] + args
        (self.run_dir / "cmdline.txt").write_text(" ".join(cmd) + "\n")
        stderr = (self.run_dir / "qemu.stderr").open("wb")
        self.started_at = time.monotonic()
        self._proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=stderr, stderr=stderr)
        stderr.close()
        try:
            for i, (ls, u) in enumerate(zip(listeners, uart_defs)):
                try:
                    conn, _ = ls.accept()
                except socket.timeout:
                    raise QemuError(f"QEMU did not connect {u['name']}; see {self.run_dir}/qemu.stderr") from None
                conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                self.uarts.append(Uart(str(u["name"]), conn, self.run_dir / f"{u['name']}.log",
                                       on_timeout=self.dump_state))
            self._qmp = Qmp(qmp_path)
        except BaseException:
            self._failed = True
            self.stop()
            raise
        finally:
            for ls in listeners:
                ls.close()
        return self

    def uart(self, which: int | str) -> Uart:
        if isinstance(which, int):
            return self.uarts[which]
        for u in self.uarts:
            if u.name == which:
                return u
        raise QemuError(f"no UART {which!r} (have {[u.name for u in self.uarts]})")

    def pause(self) -> None:
        """Stops the guest (QMP ``stop``): guest time stands still, its
        sockets stay open, until resume()."""
        if self._qmp is None:
            raise QemuError("QEMU is not running")
        self._qmp.execute("stop")

    def resume(self) -> None:
        """Lets a paused guest run on (QMP ``cont``)."""
        if self._qmp is None:
            raise QemuError("QEMU is not running")
        self._qmp.execute("cont")

    def hmp(self, command: str, cpu: int | None = None) -> str:
        """A human-monitor command (e.g. ``xp /4wx 0xffff8000``), on the
        given CPU's context for CPU-specific ones (``info registers``)."""
        if self._qmp is None:
            raise QemuError("QEMU is not running")
        args: dict[str, Any] = {"command-line": command}
        if cpu is not None:
            args["cpu-index"] = cpu
        out = self._qmp.execute("human-monitor-command", **args)
        return str(out)

    def read_word(self, addr: int) -> int:
        """A 32-bit word of guest physical memory, read through the monitor."""
        out = self.hmp(f"xp /1wx {addr:#x}")
        m = re.search(r":\s*(0x[0-9a-fA-F]+)", out)
        if not m:
            raise QemuError(f"cannot parse xp output: {out!r}")
        return int(m.group(1), 16)

    def wait_word(self, addr: int, value: int, timeout: float = 5.0, interval: float = 0.05) -> float:
        """Poll a word until it equals ``value``; return the seconds waited."""
        t0 = time.monotonic()
        while True:
            if self.read_word(addr) == value:
                return time.monotonic() - t0
            if time.monotonic() - t0 > timeout:
                raise QemuError(f"word at {addr:#x} is {self.read_word(addr):#x}, not {value:#x} after {timeout:g} s")
            time.sleep(interval)

    def mark_failed(self) -> None:
        """Keep the run directory whatever happens at stop()."""
        self._failed = True

    def dump_state(self, reason: str = "requested") -> Path | None:
        """Write every vCPU's registers (QMP ``info registers``, the PC and
        LR symbolised, and a scan of the stack for code addresses) into ``vcpu-state.txt``
        in the run directory (appended, so several dumps of one run are
        kept), with the VM paused meanwhile; mark the run failed so the
        logs are kept. Called by the UARTs when a wait times out."""
        if self._qmp is None or self.run_dir is None or not self.running:
            return None
        self._failed = True
        out = self.run_dir / "vcpu-state.txt"
        # two snapshots a host second apart: a PC that moves is a livelock
        # or a busy loop, one that does not is a deadlock or a halted CPU
        with out.open("a") as f:
            f.write(vcpu_report(self, reason))
            time.sleep(1.0)
            f.write(vcpu_report(self, reason + " (1 s later)"))
        _log(f"{reason}: vCPU state in {out}")
        return out

    @property
    def running(self) -> bool:
        return self._proc is not None and self._proc.poll() is None

    def stop(self, timeout: float = 5.0) -> int | None:
        """Quit QEMU (QMP quit, then SIGTERM, then SIGKILL), close the UARTs,
        and remove the run directory unless something failed or keep_logs."""
        rc: int | None = None
        if self._proc is not None:
            if self._proc.poll() is None and self._qmp is not None:
                try:
                    self._qmp.execute("quit")
                except (QemuError, OSError):
                    pass
            for sig in (None, signal.SIGTERM, signal.SIGKILL):
                if sig is not None and self._proc.poll() is None:
                    self._proc.send_signal(sig)
                try:
                    rc = self._proc.wait(timeout=timeout)
                    break
                except subprocess.TimeoutExpired:
                    continue
            self._proc = None
        if self._qmp is not None:
            self._qmp.close()
            self._qmp = None
        for u in self.uarts:
            u.close()
        self.uarts = []
        if getattr(self, "_sockdir", None) is not None:
            shutil.rmtree(self._sockdir, ignore_errors=True)
        if self.run_dir is not None:
            if self._failed or self.keep_logs:
                _log(f"logs kept in {self.run_dir}")
            else:
                shutil.rmtree(self.run_dir, ignore_errors=True)
        return rc

    def __enter__(self) -> QemuMachine:
        return self.start() if self._proc is None else self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if exc_type is not None:
            self._failed = True
        self.stop()


@dataclass(frozen=True)
class BootTimes:
    """Host seconds from QEMU start to the first kernel line and the shell."""

    first_line: float
    shell: float
    guest_userspace: float


def boot_to_shell(machine: QemuMachine, timeout: float = 60.0) -> BootTimes:
    """Wait until the console shell is usable; return the timings."""
    console = machine.uart(0)
    prompt = str(machine.board.data["linux"]["prompt"])
    console.wait_for_line("Booting Linux", timeout=timeout)
    first = time.monotonic() - machine.started_at
    line = console.wait_for_line(r"servoamp: userspace ready at ([0-9.]+) s", timeout=timeout, regex=True)
    m = re.search(r"ready at ([0-9.]+) s", line)
    console.wait_for_text(prompt, timeout=timeout)
    shell = time.monotonic() - machine.started_at
    return BootTimes(first_line=first, shell=shell, guest_userspace=float(m.group(1)) if m else -1.0)


def run_shell(console: Uart, command: str, prompt: str, timeout: float = 20.0) -> tuple[int, str]:
    """Run ``command`` in the guest shell on ``console``; return its exit
    status and output (without the echoed command line).

    The output is framed by markers that are printed through a format
    string, so the echoed command line (which the shell may wrap anywhere)
    never matches them.
    """
    console.write_line(f"printf '__%s__\\n' beg; {command}; printf '\\n__rc=%d__\\n' $?")
    console.wait_for_line(r"^__beg__$", timeout=timeout, regex=True)
    begin = console.cursor
    rc_line = console.wait_for_line(r"^__rc=\d+__$", timeout=timeout, regex=True)
    end = console.cursor - len(rc_line) - 1
    text = console.output[begin:end]
    text = text[:-1] if text.endswith("\n") else text  # printf's leading newline
    console.wait_for_text(prompt, timeout=timeout)
    return int(rc_line[5:-2]), text.rstrip("\n")


def interactive(board: Board, images: Images, accel: str | None = None, uart1_log: Path | None = None,
                extra_args: Sequence[str] = (), clock: str | None = None, icount: str | None = None,
                can_links: Mapping[int, str | Path] | None = None,
                can_link_opts: Mapping[str, int] | None = None) -> int:
    """Boot with UART0 (and the QEMU monitor: Ctrl-A c) on this terminal and
    UART1 in a log file; return QEMU's exit code. ``can_links``: see
    :func:`can_args`."""
    binary = check_qemu(board)
    uart1_log = uart1_log or (REPO / "build" / "qemu" / "uart1.log")
    uart1_log.parent.mkdir(parents=True, exist_ok=True)
    serials = ["mon:stdio", f"file:{uart1_log}"]
    cmd = [binary] + qemu_args(board, images, serials, accel, clock, icount, can_links,
                               can_link_opts) + list(extra_args)
    _log("UART0 (Linux console) on this terminal; Ctrl-A x quits, Ctrl-A c is the monitor")
    _log(f"UART1 (servo core) in {uart1_log}")
    return subprocess.call(cmd)


def iter_word_samples(machine: QemuMachine, addr: int, count: int, interval: float) -> Iterator[int]:
    """``count`` reads of a word, ``interval`` seconds apart."""
    for i in range(count):
        if i:
            time.sleep(interval)
        yield machine.read_word(addr)


# --------------------------------------------------------------------------
# vCPU state on a hang
# --------------------------------------------------------------------------


class Symbols:
    """Address to ``symbol+0xoff`` for an ELF (``nm -n``), loaded once."""

    _cache: dict[Path, Symbols] = {}

    def __init__(self, elf: Path) -> None:
        self.elf = elf
        self.addrs: list[int] = []
        self.names: list[str] = []
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


def _symbol_files(cpu: int) -> list[Path]:
    """Where an address of ``cpu`` may come from: CPU0 runs Linux (vmlinux)
    and servod; CPU1 the servo firmware (its ELF) or the boot stub."""
    if cpu == 0:
        return [kernel_link() / "obj/vmlinux", REPO / "build/linux/servod/servod"]
    return sorted((REPO / "build/rpu_app").glob("*/servo.elf"))


def symbolise(cpu: int, addr: int, board: Board | None = None) -> str:
    if board is not None:
        stub = board.addr("load", "boot_stub")
        if stub <= addr < stub + 0x1000:
            park = board.addr("load", "park_loop")
            return f"boot stub{' (park loop)' if addr >= park else ''}+{addr - stub:#x}"
    for f in _symbol_files(cpu):
        syms = Symbols.of(f)
        hit = syms.lookup(addr) if syms else None
        if hit:
            return f"{hit} ({f.name})"
    return "?"


_REG = re.compile(r"R(\d\d)=([0-9a-fA-F]{8})")


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
        vmlinux = kernel_link() / "obj/vmlinux"
        if vmlinux.exists():
            nm = shutil.which("arm-linux-gnueabihf-nm") or "nm"
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
