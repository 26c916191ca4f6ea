"""Run a board in QEMU: the command line from the board's numbers, the
machine (:class:`QemuMachine`: UARTs on TCP sockets, QMP, clean shutdown,
logs kept on failure) and the waits on its console. Part of the launcher
that :mod:`servoamp.qemu` re-exports."""

from __future__ import annotations

import os
import re
import shutil
import signal
import socket
import subprocess
import time
import weakref
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from servoamp.board import REPO, Board, QemuError, _log
from servoamp.hoststall import StallMeter
from servoamp.images import Images, _run
from servoamp.qmp import Qmp
from servoamp.uart import Uart
from servoamp.vcpu import vcpu_report


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


# A binary that runs every board's machine (qemu-system-aarch64 also runs
# xilinx-zynq-a9)
QEMU_ANY_BOARD = "qemu-system-aarch64"
_FALLBACK_NOTED: set[str] = set()
# the machines started and not stopped yet (mark_running_failed)
_RUNNING: dict[int, weakref.ref[QemuMachine]] = {}


def mark_running_failed() -> int:
    """Keep the logs of every machine still running (a test failed while
    they ran: tests/conftest.py calls this, so a board that a module's
    fixture keeps for several tests keeps its logs when one of them fails);
    how many."""
    machines = [m for m in (r() for r in list(_RUNNING.values())) if m is not None]
    for m in machines:
        m.mark_failed()
    return len(machines)


def check_qemu(board: Board) -> str:
    """Path of the QEMU binary: $SERVOAMP_QEMU when set (and a binary that
    runs the board: the board's own, or qemu-system-aarch64), else the
    project's own build (:func:`project_qemu`), else, for a board whose
    binary our build does not make yet (qemu-system-aarch64 for the ZynqMP,
    until emulator/qemu/build.sh builds that target), Debian's from the PATH
    (scripts/bootstrap.sh installs it), said once on the log; refuses
    versions older than the board needs."""
    name = str(board.qemu["binary"])
    env = os.environ.get("SERVOAMP_QEMU")
    if env and Path(env).name in (name, QEMU_ANY_BOARD):
        binary = env
    else:
        binary = str(project_qemu() / "bin" / name)
        debian = shutil.which(name)
        if not os.access(binary, os.X_OK) and debian:
            if name not in _FALLBACK_NOTED:
                _log(f"our QEMU build has no {name} yet: using Debian's {debian} (upstream QEMU: "
                     f"no RPU GIC, TCM or PMU)")
                _FALLBACK_NOTED.add(name)
            binary = debian
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
    machine = str(q["machine"])
    if q.get("machine_opts"):
        machine += "," + str(q["machine_opts"])
    args = [
        "-M", machine + can_machine, "-smp", str(q["smp"]), "-m", str(q["memory"]),
        "-display", "none", "-nodefaults",
    ]
    args += [str(a) for a in q.get("args") or ()]
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
    args = machine_args(board, serials, accel, clock, icount, can_links, can_link_opts)
    return args + boot_args(board, images, bool(clock_args(board, clock, icount)))


def boot_args(board: Board, images: Images, virtual_time: bool) -> list[str]:
    """The loaders of a boot (``-device loader``): the images at the
    board's load addresses and where each CPU starts, by the board's boot
    flow (:attr:`Board.boot_flow`):

    * ``stub`` (Zynq-7000): the boot stub (its -icount variant under
      virtual time), zImage, DTB, initramfs; every CPU starts in the stub;
    * ``tf-a`` (ZynqMP): BL31, the BL33 stub, Image, DTB, initramfs; CPU0
      starts at BL31's entry (EL3, as after the boot ROM and FSBL on
      hardware), the other cores stay powered off (QEMU's reset state) for
      PSCI or the RPU's reset control to start.
    """
    args: list[str] = []
    if board.boot_flow == "tf-a":
        if images.bl31 is None:
            raise QemuError(f"board {board.name} boots through TF-A: the images have no BL31")
        tf_a_loads = [
            (images.bl31, board.addr("load", "tf_a")),
            (images.stub, board.addr("load", "bl33")),
            (images.kernel, board.addr("load", "image")),
            (images.dtb, board.addr("load", "dtb")),
            (images.initramfs, board.addr("load", "initramfs")),
        ]
        for path, addr in tf_a_loads:
            args += ["-device", f"loader,file={path},addr={addr:#x},force-raw=on"]
        return args + ["-device", f"loader,addr={board.addr('load', 'tf_a'):#x},cpu-num=0"]
    if board.boot_flow != "stub":
        raise QemuError(f"board {board.name}: unknown boot flow {board.boot_flow!r} (stub, tf-a)")
    stub = board.addr("load", "boot_stub")
    timebase = virtual_time
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
    for cpu in range(int(board.qemu["smp"])):
        args += ["-device", f"loader,addr={stub:#x},cpu-num={cpu}"]
    return args


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
        _RUNNING[id(self)] = weakref.ref(self)
        stderr.close()
        proc = self._proc
        stall = StallMeter(lambda: (proc.pid, os.getpid()))
        try:
            for i, (ls, u) in enumerate(zip(listeners, uart_defs)):
                try:
                    conn, _ = ls.accept()
                except socket.timeout:
                    raise QemuError(f"QEMU did not connect {u['name']}; see {self.run_dir}/qemu.stderr") from None
                conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                self.uarts.append(Uart(str(u["name"]), conn, self.run_dir / f"{u['name']}.log",
                                       on_timeout=self.dump_state, stall=stall))
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
        _RUNNING.pop(id(self), None)
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
