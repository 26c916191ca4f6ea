"""``west emu``: build what is missing and boot the emulated board in QEMU.

    west emu                         # interactive: Linux console here
    west emu -c 'cat /proc/cpuinfo'  # scripted: boot, run, print, quit
    west emu --script cmds.sh        # scripted, one shell command a line
    west emu --build-only            # just build/refresh the images
    west emu --kernel rt             # boot the PREEMPT_RT kernel (build.sh --variant rt)
    west emu --net                   # with guest networking (eth0 up, servod's
                                     # telemetry port forwarded to 127.0.0.1)
    west emu -b zynqmp_qemu          # the ZynqMP: TF-A, then Linux 6.12 arm64 on one A53

What it builds (each step is cached and costs about a second when nothing
changed): the kernel (linux/kernel/build.sh: the PREEMPT_RT kernel, cached
by source + RT patch series + config fragments; with --kernel vanilla or
SERVOAMP_KERNEL=vanilla the non-preemptible one, cached by source +
fragment), the remoteproc
module, rpu_app (its Makefile, when it exists), the test firmware
(tests/robot/fixtures), the initramfs, the boot stub and the DTB. The
board's numbers come from boards/<board>/board.yaml.

Interactive mode: UART0 (the Linux console) and the QEMU monitor share this
terminal (Ctrl-A c switches to the monitor, Ctrl-A x quits); UART1 (the
servo core's console) goes to a log file. Scripted mode: UARTs on sockets
bound to 127.0.0.1, the monitor on QMP; exits non-zero when a command fails.

--net [PORT]: gem0 on QEMU user networking, with the host's 127.0.0.1:PORT
(a free port when PORT is left out) forwarded to the guest's telemetry port
(board.yaml "network"). Scripted mode brings eth0 up first (servoamp-net);
interactive mode prints the command to do it. servod's telemetry listens on
the guest's loopback unless told otherwise: start it with `servod
--telemetry 10.0.2.15:7700 --telemetry-token FILE` in the guest, then
`servoamp record --connect 127.0.0.1:PORT --token-file FILE -o run.mcap`
on the host records the controller (docs/telemetry.md, "Who may connect"),
and `servoamp bridge --connect 127.0.0.1:PORT --token-file FILE [--mcap
run.mcap]` serves it live to Foxglove on ws://127.0.0.1:8765 (printed).

Also runs without a west workspace: ``.venv/bin/python scripts/west_commands/emu.py``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "python"))

from servoamp import netboard, qemu  # noqa: E402

DESCRIPTION = "build what is missing and boot the emulated board (QEMU)"


def add_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    parser.add_argument("-b", "--board", default="zynq7000_qemu", help="board folder under boards/ (default: %(default)s)")
    parser.add_argument("--accel", default=None, help="QEMU -accel value, e.g. 'tcg,thread=single' (default: QEMU's, multi-threaded TCG)")
    parser.add_argument("--host-time", action="store_true",
                        help="guest time follows the host clock (for interactive use) instead of counting "
                             "instructions (-icount, board.yaml qemu.clock, the default): on the host clock "
                             "host load can make the guest miss cycles (docs/cycle.md)")
    parser.add_argument("--icount", default=None, metavar="SPEC",
                        help="virtual time with this -icount value instead of the board's "
                             "(one instruction = 2^shift ns)")
    parser.add_argument("--kernel", choices=qemu.KERNELS, default=None,
                        help="kernel variant: rt (PREEMPT_RT) or vanilla (non-preemptible 6.1); "
                             "default: $SERVOAMP_KERNEL, else rt")
    parser.add_argument("--firmware", action="append", type=Path, default=None, metavar="ELF",
                        help="ELF to put in /lib/firmware (repeatable; default: test fixtures + rpu_app)")
    parser.add_argument("--no-rpu-app", action="store_true", help="do not build or include rpu_app")
    parser.add_argument("-c", "--command", action="append", default=[], metavar="CMD",
                        help="scripted mode: run CMD in the guest shell (repeatable)")
    parser.add_argument("--script", type=Path, help="scripted mode: run each line of this file in the guest shell")
    parser.add_argument("--timeout", type=float, default=60.0, help="seconds per boot or command in scripted mode")
    parser.add_argument("--keep-logs", action="store_true", help="keep build/qemu/<run>/ (UART logs) even on success")
    parser.add_argument("--build-only", action="store_true", help="build the images, do not boot")
    parser.add_argument("--net", nargs="?", type=int, const=0, default=None, metavar="PORT",
                        help="guest networking: forward 127.0.0.1:PORT (default: a free port) to the "
                             "guest's telemetry port; scripted mode brings eth0 up first")
    return parser


def net_args(board: qemu.Board, port: int | None) -> tuple[list[str], int | None]:
    """QEMU arguments for --net, and the host port (None without --net)."""
    if port is None:
        return [], None
    if not 0 <= port <= 65535:
        raise qemu.QemuError(f"--net: port {port} is not a TCP port")
    net = board.data["network"]
    host_port = port or netboard.free_port()
    print(f"[emu] network: {net['nic']} (eth0, {net['guest_addr']}), "
          f"host 127.0.0.1:{host_port} -> guest :{net['telemetry_port']}")
    print(f"[emu] live in Foxglove: .venv/bin/servoamp bridge --connect 127.0.0.1:{host_port} "
          f"--token-file FILE [--mcap run.mcap], then open the ws://127.0.0.1:8765/?token=... "
          f"URL it prints (Open connection > Foxglove WebSocket)")
    return netboard.nic_args(host_port, int(net["telemetry_port"]), str(net["nic"])), host_port


def run(args: argparse.Namespace) -> int:
    board = qemu.Board.load(args.board)
    if args.kernel:
        # the launcher (kernel_dir(), the vmlinux of the register dumps) follows it
        os.environ["SERVOAMP_KERNEL"] = args.kernel
    print(f"[emu] kernel: {qemu.default_kernel()}")
    t0 = time.monotonic()
    images = qemu.prepare_images(board, args.firmware, with_rpu_app=not args.no_rpu_app)
    print(f"[emu] images ready in {time.monotonic() - t0:.1f} s")
    for name in ("bl31", "stub", "zimage", "dtb", "initramfs"):
        if getattr(images, name) is not None:
            print(f"[emu]   {name:9} {getattr(images, name)}")
    print(f"[emu]   firmware  {' '.join(p.name for p in images.firmware) or '-'}")
    if args.build_only:
        return 0

    commands = list(args.command)
    if args.script:
        commands += [ln for ln in args.script.read_text().splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    nic, host_port = net_args(board, args.net)
    extra = nic
    if args.host_time and args.icount:
        print("[emu] --host-time and --icount exclude each other", file=sys.stderr)
        return 2
    clock = "host" if args.host_time else ("virtual" if args.icount else None)
    print(f"[emu] clock: {' '.join(qemu.clock_args(board, clock, args.icount)) or 'host'}")
    if not commands:
        if host_port is not None:
            print(f"[emu] in the guest, bring eth0 up with: servoamp-net {board.data['network']['guest_addr']}")
            print("[emu] then serve telemetry with: head -c 24 /dev/urandom | od -An -tx1 | tr -d ' \\n' "
                  "> /tmp/token; chmod 600 /tmp/token; servod --telemetry 10.0.2.15:7700 --telemetry-token /tmp/token &")
            print(f"[emu] and record on the host (token copied from the guest's /tmp/token): "
                  f".venv/bin/servoamp record --connect 127.0.0.1:{host_port} --token TOKEN -o run.mcap")
            print(f"[emu] or watch it live: .venv/bin/servoamp bridge --connect 127.0.0.1:{host_port} "
                  f"--token TOKEN --mcap run.mcap, and open ws://127.0.0.1:8765 in Foxglove")
        return qemu.interactive(board, images, accel=args.accel, extra_args=extra, clock=clock, icount=args.icount)
    return scripted(board, images, commands, args, extra, clock, net=host_port is not None)


def scripted(board: qemu.Board, images: qemu.Images, commands: list[str], args: argparse.Namespace,
             extra: list[str], clock: str | None, net: bool = False) -> int:
    machine = qemu.QemuMachine(board, images, accel=args.accel, keep_logs=args.keep_logs, extra_args=extra,
                               clock=clock, icount=args.icount)
    failed = 0
    with machine:
        times = qemu.boot_to_shell(machine, timeout=args.timeout)
        print(f"[emu] shell after {times.shell:.2f} s (host; first kernel line {times.first_line:.2f} s, "
              f"userspace at {times.guest_userspace:.2f} s guest uptime)")
        console = machine.uart(0)
        prompt = str(board.data["linux"]["prompt"])
        if net:
            try:
                print(netboard.bring_up(console, prompt, str(board.data["network"]["guest_addr"]),
                                        timeout=args.timeout))
            except qemu.QemuError as e:
                print(f"[emu] {e}")
                machine.mark_failed()
                return 1
        for cmd in commands:
            rc, out = qemu.run_shell(console, cmd, prompt, timeout=args.timeout)
            print(f"$ {cmd}")
            if out:
                print(out)
            if rc:
                print(f"[emu] exit status {rc}")
                failed += 1
        uart1 = machine.uart(1).output
        if uart1:
            print("[emu] UART1 (servo core):")
            print(uart1.rstrip("\n"))
        if failed:
            machine.mark_failed()
    return 1 if failed else 0


try:
    from west.commands import WestCommand

    class Emu(WestCommand):
        def __init__(self) -> None:
            super().__init__("emu", DESCRIPTION, __doc__ or "", accepts_unknown_args=False)

        def do_add_parser(self, parser_adder):  # type: ignore[no-untyped-def]
            parser = parser_adder.add_parser(self.name, help=self.help, description=self.description,
                                             formatter_class=argparse.RawDescriptionHelpFormatter)
            return add_arguments(parser)

        def do_run(self, args, unknown):  # type: ignore[no-untyped-def]
            try:
                rc = run(args)
            except qemu.QemuError as e:
                self.die(str(e))
            if rc:
                sys.exit(rc)

except ImportError:  # plain Python, no west
    pass


if __name__ == "__main__":
    p = add_arguments(argparse.ArgumentParser(prog="emu", description=__doc__,
                                              formatter_class=argparse.RawDescriptionHelpFormatter))
    sys.exit(run(p.parse_args()))
