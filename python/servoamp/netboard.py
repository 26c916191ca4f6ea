"""The emulated controller with guest networking, for recording its telemetry.

QEMU user networking gives the board's gem0 (Cadence GEM, eth0 in the guest,
10.0.2.15/24) a host port forward bound to 127.0.0.1 only, to servod's
telemetry port (7700):

    -nic user,model=cadence_gem,hostfwd=tcp:127.0.0.1:HOSTPORT-:7700

:class:`ControllerBoard` boots the board with that NIC (through
``QemuMachine(extra_args=...)``), brings eth0 up (``servoamp-net`` in the
initramfs), starts servod and the servo firmware, and runs shell commands
and ``ampctl`` on the console::

    with ControllerBoard() as cb:
        cb.start_servod()
        cb.start_firmware()
        res = servoamp.record.record("127.0.0.1", cb.host_port, "run.mcap", 5.0,
                                     token=cb.token)

servod listens on loopback only unless told otherwise, and anything else
needs a token (docs/telemetry.md). The forward reaches the guest's
10.0.2.15, so :meth:`ControllerBoard.start_servod` passes
``--telemetry 10.0.2.15:7700 --telemetry-token /tmp/telemetry.token`` with a
fresh random token (``cb.token``) that it writes into the guest first.
"""

from __future__ import annotations

import re
import secrets
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import IO, Any, Callable, Mapping, Sequence

from servoamp import qemu
from servoamp import telemetry as tw

# The defaults of a board's network entry (board.yaml ``network:``; a
# ControllerBoard takes its board's values); tests/robot/test_board_contract.py
# checks that they agree with the Zynq-7000's.
TELEMETRY_PORT = 7700
GUEST_ADDR = "10.0.2.15/24"
NIC_MODEL = "cadence_gem"
SERVOD_LOG = "/tmp/servod.log"
TOKEN_FILE = "/tmp/telemetry.token"
WAIT_POLL_S = 0.5  # ControllerBoard.wait_status: guest seconds between two polls
# Guest shell: the servo core's remoteproc directory
# (/sys/class/remoteproc/remoteprocN), found by servod as it finds it
# (linux/servod/rproc.c: the remoteproc the OCM mailbox's devicetree node
# names in servoamp,remoteproc). Guest scripts write
# ``RPROC=$(servod --find-rproc)``, as scripts/demo/guest-commands.sh does.
FIND_RPROC = "servod --find-rproc"


def servod_board_args(board: qemu.Board) -> str:
    """servod's options that name the board: its controller id (the
    board's name, in the telemetry's HELLO and the recordings) and the rate
    of the servo core's time base (board.yaml servo.clock_hz: the
    feedback's t_cycle, which the bridge puts the CAN frames on). The demo
    passes them too (scripts/demo.sh: ``python -m servoamp.netboard
    --servod-args BOARD``)."""
    hz = board.servo.get("clock_hz")
    return f"--id {board.name}" + (f" --servo-clock-hz {int(hz)}" if hz else "")


def find_rproc(sh: Callable[[str], str]) -> str:
    """The servo core's remoteproc directory in the guest (:data:`FIND_RPROC`
    through ``sh``, a guest shell), or QemuError when servod finds none."""
    out = sh(f"{FIND_RPROC} 2>&1")
    found: list[str] = re.findall(r"^(/sys/class/remoteproc/remoteproc\d+)\s*$", out, re.M)
    if len(found) != 1:
        raise qemu.QemuError(f"{FIND_RPROC} found no servo core's remoteproc: {out.strip()!r}")
    return found[0]


def stop_contract(board: qemu.Board) -> bool:
    """Whether the board's servo firmware has the cooperative stop (STOP,
    the STOPPING state word, PRKD and the park loop: rpu_app's platform,
    BOARD_HAS_STOP_CONTRACT in the board_config.h its build generated;
    rpu_app/README.md). The ZynqMP's R5 has not: the upstream driver powers
    the core down without asking it."""
    h = qemu.REPO / "build" / "rpu_app" / board.name / "board_config.h"
    m = re.search(r"^#define BOARD_HAS_STOP_CONTRACT\s+(?:BOARD_U\()?(\d+)", h.read_text(), re.M)
    if m is None:
        raise qemu.QemuError(f"{h}: no BOARD_HAS_STOP_CONTRACT (rpu_app not built for {board.name}?)")
    return m.group(1) != "0"


def free_port() -> int:
    """A TCP port on 127.0.0.1 that is free now (QEMU binds it right after)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def nic_args(host_port: int, guest_port: int = TELEMETRY_PORT, model: str = NIC_MODEL) -> list[str]:
    """QEMU arguments: gem0 on user networking, host 127.0.0.1:host_port
    forwarded to the guest's guest_port."""
    return ["-nic", f"user,model={model},hostfwd=tcp:127.0.0.1:{host_port}-:{guest_port}"]


def bring_up(console: qemu.Uart, prompt: str, guest_addr: str = GUEST_ADDR,
             timeout: float = 20.0) -> str:
    """Bring the guest's eth0 up (``servoamp-net`` in the initramfs) on the
    shell of ``console``; return its output, or raise QemuError when the
    command fails or the link has no carrier."""
    rc, out = qemu.run_shell(console, f"servoamp-net {guest_addr}", prompt, timeout=timeout)
    if rc or "carrier 1" not in out:
        raise qemu.QemuError(f"guest network not up (exit status {rc}): {out}")
    return out


def parse_kv(out: str) -> dict[str, str]:
    """ampctl's key=value lines; a line of several key=value words
    ("axis0.drive=... axis0.error=...") gives each."""
    kv: dict[str, str] = {}
    for line in out.splitlines():
        words = line.split()
        parts = words if len(words) > 1 and all("=" in w for w in words) else [line]
        for w in parts:
            k, eq, v = w.partition("=")
            if eq:
                kv[k] = v
    return kv


def _log(msg: str) -> None:
    print(f"[netboard] {msg}", flush=True)


class ControllerBoard:
    """One boot of the emulated controller with networking."""

    def __init__(self, board: qemu.Board | None = None, images: qemu.Images | None = None,
                 host_port: int | None = None, accel: str | None = "tcg,thread=single",
                 keep_logs: bool = False, extra_args: Sequence[str] = (),
                 clock: str | None = None, icount: str | None = None,
                 can_drives: Mapping[int, str] | None = None, can_log: Path | None = None,
                 can_link_opts: Mapping[str, int] | None = None,
                 drivesim_args: Sequence[str] = ()) -> None:
        self.board = board or qemu.Board.load("zynq7000_qemu")
        self.images = images
        self.host_port = host_port or free_port()
        self.accel = accel
        self.keep_logs = keep_logs
        self.extra_args = list(extra_args)
        self.clock = clock              # None: qemu.default_clock()
        self.icount = icount            # virtual time: -icount spec instead of the board's
        self.machine: qemu.QemuMachine | None = None
        self.boot_times: qemu.BootTimes | None = None
        self.prompt = str(self.board.data["linux"]["prompt"])
        net = dict(self.board.data.get("network") or {})
        self.guest_addr = str(net.get("guest_addr", GUEST_ADDR))
        self.nic_model = str(net.get("nic", NIC_MODEL))
        self.telemetry_port = int(net.get("telemetry_port", TELEMETRY_PORT))
        self.rproc = ""                 # the servo core's remoteproc (found after the boot)
        self.token = secrets.token_hex(16)  # servod's --telemetry-token, per boot
        # CAN (docs/canlink.md, docs/fieldbus.md): bus (0: CAN0, 1: CAN1) ->
        # the drive simulator's --nodes on it; each bus linked in lockstep to
        # its own servoamp-drivesim, and with can_log (a directory) an active
        # python-can logger (it only sends DONEs: QEMU waits for it) per bus writing can_log/canN.asc (every frame on
        # the bus, whole once QEMU has quit)
        self.can_drives = dict(can_drives or {})
        self.can_log = can_log
        # a simulator or logger held up on a loaded host must not cost the
        # guest an answer (canlink drops what comes after timeout-ms): 10 s
        # here, against the backend's 200 ms; a dead one closes its socket
        # and is dropped at once
        self.can_link_opts = {"timeout-ms": 10_000} | dict(can_link_opts or {})
        self.drivesim_args = list(drivesim_args)
        self.can_socks: dict[int, Path] = {}
        self.can_procs: list[tuple[str, subprocess.Popen[bytes], IO[bytes]]] = []
        self._can_dir: Path | None = None

    # -- lifecycle -------------------------------------------------------------------
    def start(self, timeout: float = 90.0) -> ControllerBoard:
        if self.images is None:
            self.images = qemu.prepare_images(self.board)
        if self.can_drives:
            # Unix socket names are short: a directory under /tmp
            self._can_dir = Path(tempfile.mkdtemp(prefix="servoamp-can-"))
            self.can_socks = {b: self._can_dir / f"can{b}.sock" for b in sorted(self.can_drives)}
        self.machine = qemu.QemuMachine(self.board, self.images, accel=self.accel,
                                        keep_logs=self.keep_logs, clock=self.clock,
                                        icount=self.icount,
                                        extra_args=nic_args(self.host_port, self.telemetry_port,
                                                            self.nic_model) + self.extra_args,
                                        can_links=self.can_socks or None,
                                        can_link_opts=self.can_link_opts or None)
        self.machine.start()
        try:
            # the drives connect while Linux boots: the firmware, started
            # later through remoteproc, is the first to send on the bus
            for b, nodes in sorted(self.can_drives.items()):
                self._can_proc(f"drivesim{b}", [sys.executable, "-m", "servoamp.drivesim", "--socket",
                                                str(self.can_socks[b]), "--nodes", nodes, "--wait", "60",
                                                "--control", str(self._drive_ctl(b)), "-v",
                                                *self.drivesim_args])
                if self.can_log is not None:
                    self.can_log.mkdir(parents=True, exist_ok=True)
                    # a listener: QEMU waits for it as for the drives, so
                    # a logger that falls behind holds the guest instead of
                    # filling its socket and being dropped (every frame
                    # logged), and it gets only the frames that made it (a
                    # frame a bus error destroyed is an error frame)
                    self._can_proc(f"canlog{b}", [sys.executable, "-m", "can.logger", "-i", "servoamp",
                                                  "-c", str(self.can_socks[b]), "-f",
                                                  str(self.can_log_path(b)), "--bus-kwargs",
                                                  "listen_only=true"])
            self.boot_times = qemu.boot_to_shell(self.machine, timeout=timeout)
            bring_up(self.machine.uart(0), self.prompt, self.guest_addr, timeout=20)
            self.rproc = find_rproc(lambda c: self.sh(c, expected_rc=None))
        except BaseException:
            self.machine.mark_failed()
            self.stop()
            raise
        return self

    def _can_proc(self, name: str, cmd: list[str]) -> None:
        assert self.machine is not None and self.machine.run_dir is not None
        log = open(self.machine.run_dir / f"{name}.log", "wb")
        self.can_procs.append((name, subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT,
                                                      cwd=qemu.REPO), log))

    def _drive_ctl(self, bus: int) -> Path:
        assert self._can_dir is not None
        return self._can_dir / f"drives{bus}.ctl"

    def drives(self, bus: int, request: str, timeout: float = 30.0) -> str:
        """A request to the drive simulator of a bus ('fault NODE KIND',
        'state': servoamp-drivesim --control); its answer ('ok ...'), or
        QemuError."""
        from servoamp.drivesim.__main__ import control_request

        deadline = time.monotonic() + timeout
        while True:     # the simulator makes its socket once QEMU's link is up
            try:
                ans = control_request(self._drive_ctl(bus), request, timeout)
                break
            except (FileNotFoundError, ConnectionRefusedError):
                if time.monotonic() > deadline:
                    raise qemu.QemuError(f"drive simulator of can{bus}: no control socket") from None
                time.sleep(0.1)
        if not ans.startswith("ok"):
            raise qemu.QemuError(f"drive simulator of can{bus}: {request!r}: {ans}")
        return ans

    def can_log_path(self, bus: int) -> Path:
        """The logger's ASC file of a bus (can_log: its directory)."""
        assert self.can_log is not None
        return self.can_log / f"can{bus}.asc"

    def stop(self) -> None:
        if self.machine is not None:
            self.machine.stop()
            self.machine = None
        # QEMU said BYE when it quit: the simulators and loggers end on it
        for name, proc, log in self.can_procs:
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.terminate()
                try:
                    proc.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait()
            log.close()
        self.can_procs = []
        if self._can_dir is not None:
            shutil.rmtree(self._can_dir, ignore_errors=True)
            self._can_dir = None

    def mark_failed(self) -> None:
        if self.machine is not None:
            self.machine.mark_failed()

    def __enter__(self) -> ControllerBoard:
        return self.start() if self.machine is None else self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if exc_type is not None:
            self.mark_failed()
        self.stop()

    @property
    def run_dir(self) -> Path | None:
        return self.machine.run_dir if self.machine is not None else None

    # -- shell -------------------------------------------------------------------------
    def sh_rc(self, command: str, timeout: float = 20.0) -> tuple[int, str]:
        if self.machine is None:
            raise qemu.QemuError("the board is not running")
        return qemu.run_shell(self.machine.uart(0), command, self.prompt, timeout=timeout)

    def sh(self, command: str, timeout: float = 20.0, expected_rc: int | None = 0) -> str:
        rc, out = self.sh_rc(command, timeout)
        if expected_rc is not None and rc != expected_rc:
            raise qemu.QemuError(f"'{command}' exited with {rc}, expected {expected_rc}:\n{out}")
        return out

    def wait_servod_log(self, text: str, count: int = 1, timeout: float = 30.0) -> None:
        tries = int(timeout / 0.05)
        out = self.sh(f'i=0; while [ "$(grep -c "{text}" {SERVOD_LOG})" -lt {count} ] && '
                      f'[ $i -lt {tries} ]; do sleep 0.05; i=$((i+1)); done; '
                      f'grep -c "{text}" {SERVOD_LOG}', timeout=timeout + 30, expected_rc=None)
        n = int(out.strip().splitlines()[-1]) if out.strip() else 0
        if n < count:
            log = self.sh(f"cat {SERVOD_LOG}", expected_rc=None)
            raise qemu.QemuError(f"servod log has {n} x {text!r}, expected {count}:\n{log}")

    def ampctl(self, args: str, expected_rc: int | None = 0) -> str:
        return self.sh(f"ampctl {args} 2>&1", expected_rc=expected_rc)

    def stats(self) -> dict[str, str]:
        out = self.ampctl("stats", expected_rc=None)
        return {k: v for k, _, v in (ln.partition("=") for ln in out.splitlines()) if _}

    def status(self) -> dict[str, str]:
        """``ampctl status`` (:func:`parse_kv`)."""
        return parse_kv(self.ampctl("status", expected_rc=None))

    def wait_status(self, ok: Callable[[dict[str, str]], bool], timeout: float, what: str = "",
                    raise_on_timeout: bool = True) -> dict[str, str]:
        """Poll :meth:`status` until ``ok(status)``; the status. Paced and
        bounded in guest time (a guest ``sleep 0.5`` between polls, at most
        ``timeout`` guest seconds of them): with CAN drives in lockstep the
        guest runs slower than the host's clock, the more so on a loaded
        host, and a host-clock deadline ran out before the guest had had
        the time (a resume after a second NMT master, under ``-j 2`` with
        a busy process per core). A guest that stops answering fails
        :meth:`sh`'s own timeout. Then: QemuError, or the last status if
        not ``raise_on_timeout``."""
        polls = 0
        while True:
            st = self.status()
            if ok(st):
                return st
            if polls * WAIT_POLL_S >= timeout:
                if raise_on_timeout:
                    raise qemu.QemuError(f"{what or 'ampctl status'}: not within {timeout:g} s"
                                         f" of guest time: {st}")
                return st
            self.sh(f"sleep {WAIT_POLL_S}", timeout=120)
            polls += 1

    def has_report_crash(self) -> bool:
        """Whether the servo core's remoteproc driver has servoamp's
        ``device/report_crash`` (docs/ABI/sysfs-servoamp-remoteproc): the
        Zynq-7000's driver; the ZynqMP's upstream driver has not, and a
        stall is servod's own record there."""
        return self.sh_rc(f"[ -e {self.rproc}/device/report_crash ]")[0] == 0

    def kernel_rt(self) -> bool:
        """Whether the guest's kernel is PREEMPT_RT (``uname -v``)."""
        return "PREEMPT_RT" in self.sh("uname -v")

    # -- the controller ------------------------------------------------------------------
    def telemetry_args(self) -> str:
        """servod's options for telemetry through the forward: the guest's
        address and the token (written into the guest, mode 0600)."""
        self.sh(f"umask 077; echo {self.token} > {TOKEN_FILE}")
        return f"--telemetry {self.guest_addr.split('/')[0]}:{self.telemetry_port} --telemetry-token {TOKEN_FILE}"

    def servod_board_args(self) -> str:
        """:func:`servod_board_args` of this board."""
        return servod_board_args(self.board)

    def start_servod(self, args: str = "") -> None:
        """servod in the background, its log in /tmp/servod.log; waits until
        it runs (and, with telemetry, listens). Without a --telemetry in
        args, telemetry is on the guest's address with this boot's token;
        without --id, the board's options (:meth:`servod_board_args`)."""
        if "--telemetry" not in args:
            args = f"{self.telemetry_args()} {args}".strip()
        if "--id" not in args:
            args = f"{self.servod_board_args()} {args}".strip()
        self.sh(f"rm -f {SERVOD_LOG}; (servod {args} > {SERVOD_LOG} 2>&1 &)")
        self.wait_servod_log("waiting for the servo")

    def start_firmware(self, firmware: str = "rpu_app.elf") -> None:
        self.sh(f"echo {firmware} > {self.rproc}/firmware && echo start > {self.rproc}/state")
        self.wait_servod_log("parameter set loaded")

    def wait_telemetry(self, timeout: float = 20.0) -> tw.Hello:
        """Connect through the port forward until servod's HELLO arrives."""
        deadline = time.monotonic() + timeout
        last: Exception | None = None
        while time.monotonic() < deadline:
            try:
                with socket.create_connection(("127.0.0.1", self.host_port), timeout=2.0) as s:
                    s.settimeout(3.0)
                    s.sendall(tw.encode_auth(self.token))
                    sp = tw.FrameSplitter()
                    while True:
                        data = s.recv(4096)
                        if not data:
                            break
                        sp.feed(data)
                        for typ, off, ln in sp.frames():
                            if typ == tw.MSG_HELLO:
                                return tw.decode_hello(bytes(sp.buf[off:off + ln]))
            except OSError as e:
                last = e
            time.sleep(0.2)
        raise qemu.QemuError(f"no telemetry HELLO at 127.0.0.1:{self.host_port} "
                             f"within {timeout:g} s ({last})")


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(description="board facts for scripts (scripts/demo.sh)")
    ap.add_argument("--servod-args", metavar="BOARD", required=True,
                    help="print servod's options that name BOARD (servod_board_args)")
    a = ap.parse_args()
    print(servod_board_args(qemu.Board.load(a.servod_args)))
