"""The demo's last step: the emulated controller live in Foxglove and into MCAP.

    python -m servoamp.demo_record [--board zynq7000_qemu|zynqmp_qemu] [--seconds N] [--out build/demo]
                                   [--keep-logs] [--program] [--can] [--ws-port 8765]

Boots the emulated board (--board, default zynq7000_qemu) with networking
(gem0 on QEMU user networking, host 127.0.0.1:PORT -> guest 7700, see servoamp.netboard), starts servod and
the firmware, and runs ``servoamp bridge`` on its telemetry for N seconds
(default 5): the Foxglove WebSocket server on ws://127.0.0.1:8765 (printed;
another free port if that one is taken) and every cycle into
build/demo/run.mcap through the Foxglove SDK, while a parameter is set
through the bridge (the WebSocket protocol's parameters path: servod,
firmware, back on /servoamp/param) and the firmware is hung on purpose
(servod detects it, remoteproc recovers it); then the plots in
build/demo/plots/, ``servoamp info`` and where the files are.

With ``--program`` the axes run the squares-and-circles G-code program (a square and a
circle, examples/seed004_squares_circles.nc) through servod's motion
pipeline during the recording instead of the idle sines, so
plots/xy_path.png shows the square and the circle; the firmware hang is
then left out (it would end the program) and the recording lasts until the
program ends (and at least --seconds).

With ``--can`` the four axes are CiA 402 drives on the two CAN buses
(rpu_app-can.elf, a servoamp-drivesim per bus in lockstep, docs/fieldbus.md):
the drives' states are shown, each bus is logged by python-can
(OUT/can0.asc, can1.asc) and its load per cycle printed; the bridge
carries every frame live and into the MCAP (/servoamp/can0, /servoamp/can1).
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from pathlib import Path

from servoamp import canload, info, netboard, plot, qemu
from servoamp.bridge import Bridge
from servoamp.record import RecordResult


PROGRAM = "/usr/share/servoamp/examples/seed004_squares_circles.nc"
CAN_DRIVES = {0: "1,2", 1: "1,2"}   # bus -> node ids (boards/<board>/servo-can.dts)
PROGRAM_MAX_S = 600.0                # host seconds a program may take on record


def _wait_program(cb: netboard.ControllerBoard, timeout: float) -> str:
    """Poll ampctl status until the program is no longer running: its state."""
    st = cb.wait_status(lambda st: st.get("program.state", "?") not in ("running", "checked", "?"), timeout,
                        raise_on_timeout=False)
    return st.get("program.state", "?")


def _wait_drives(cb: netboard.ControllerBoard, n_axes: int, timeout: float = 240.0) -> list[str]:
    """Every axis's drive in "operation enabled" (ampctl status: axisN.drive=)."""
    def enabled(st: dict[str, str]) -> bool:
        drives = [v for k, v in st.items() if k.startswith("axis") and k.endswith(".drive")]
        return len(drives) >= n_axes and all(v == "operation-enabled" for v in drives)

    st = cb.wait_status(enabled, timeout, "drives in operation enabled")
    return [f"{k}={v}" for k, v in st.items() if k.startswith("axis") and k.endswith(".drive")]


def _say(msg: str) -> None:
    print(f"[demo-record] {msg}", flush=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m servoamp.demo_record", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--board", default="zynq7000_qemu",
                    help="board folder under boards/ (default: %(default)s; zynqmp_qemu: the servo on R5 0)")
    ap.add_argument("--seconds", type=float, default=5.0, help="recording length in host seconds (default 5; on virtual time the guest may run faster)")
    ap.add_argument("--out", type=Path, default=qemu.REPO / "build" / "demo",
                    help="output folder (default build/demo)")
    ap.add_argument("--port", type=int, default=0, help="host port (default: a free one)")
    ap.add_argument("--keep-logs", action="store_true", help="keep the UART logs")
    ap.add_argument("--no-fault", action="store_true", help="no firmware hang during the recording")
    ap.add_argument("--ws-port", type=int, default=8765,
                    help="the Foxglove WebSocket port on 127.0.0.1 (default 8765; taken: a free one)")
    ap.add_argument("--program", action="store_true",
                    help="run the squares-and-circles G-code program while recording")
    ap.add_argument("--can", action="store_true",
                    help="the axes on four CiA 402 drives over CAN, two per bus (rpu_app-can.elf, "
                         "servoamp-drivesim on each bus, python-can loggers: docs/fieldbus.md)")
    args = ap.parse_args(argv)
    if args.program:
        args.no_fault = True

    t0 = time.monotonic()
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    mcap = out / "run.mcap"
    board = qemu.Board.load(args.board)
    images = qemu.prepare_images(board)
    _say(f"images ready ({time.monotonic() - t0:.1f} s)")
    cb = netboard.ControllerBoard(board, images, host_port=args.port or None,
                                  keep_logs=args.keep_logs,
                                  can_drives=CAN_DRIVES if args.can else None,
                                  can_log=out if args.can else None)
    asc: dict[int, Path] = {}
    with cb:
        _say(f"{board.name}: booted with gem0 on QEMU user networking: 127.0.0.1:{cb.host_port} -> "
             f"guest {cb.guest_addr.split('/')[0]}:{cb.telemetry_port} "
             f"({time.monotonic() - t0:.1f} s)")
        cb.start_servod()
        cb.start_firmware("rpu_app-can.elf" if args.can else "rpu_app.elf")
        hello = cb.wait_telemetry()
        _say(f"servod telemetry: controller {hello.controller_id}, {hello.n_axes} axes, "
             f"period {hello.cycle_period_ns / 1e3:.0f} us")
        # a 10-cycle watchdog trips on TCG hiccups: 50 cycles, and leave SAFESTOP
        cb.ampctl("param set wd_limit 50")
        cb.ampctl("resume", expected_rc=None)
        if args.can:
            asc = {b: cb.can_log_path(b) for b in CAN_DRIVES}
            _say("CAN: " + ", ".join(f"can{b} nodes {n}" for b, n in CAN_DRIVES.items())
                 + " (servoamp-drivesim, lockstep on guest time); the servo core configures and enables them")
            _say("drives: " + " ".join(_wait_drives(cb, hello.n_axes)))

        links = cb.can_socks if args.can else None   # every CAN frame into the MCAP, live too
        try:
            b = Bridge("127.0.0.1", cb.host_port, token=cb.token, ws_port=args.ws_port, mcap=mcap,
                       can_links=links)
        except RuntimeError:  # the port is taken
            b = Bridge("127.0.0.1", cb.host_port, token=cb.token, ws_port=0, mcap=mcap,
                       can_links=links)
        box: dict[str, RecordResult] = {}
        stop = threading.Event()
        # with a program: recorded until it ends (on CAN drives in lockstep
        # the guest runs slower than the host clock), at most PROGRAM_MAX_S
        length = PROGRAM_MAX_S if args.program else args.seconds
        th = threading.Thread(target=lambda: box.update(r=b.run(length, stop=stop)))
        _say(f"live in Foxglove: {b.ws_url} (Open connection > Foxglove WebSocket; layout "
             f"tools/foxglove/servoamp-layout.json) "
             + ("until the program ends" if args.program else f"for {args.seconds:g} s (host time)"))
        _say(f"recording through the Foxglove SDK into {mcap}")
        th.start()
        t_rec = time.monotonic()
        time.sleep(min(1.5, args.seconds / 3))
        v = b.set_param("pos_kp", 70.0)
        _say(f"bridge: param set pos_kp 70 -> servod took {v:g}; ampctl param get: "
             + cb.ampctl("param get pos_kp").strip())
        if args.program:
            _say("ampctl run: " + cb.ampctl(f"run {PROGRAM}").strip())
            end = _wait_program(cb, PROGRAM_MAX_S)
            time.sleep(max(0.5, args.seconds - (time.monotonic() - t_rec)))
            stop.set()
            _say(f"program ended: {end}")
        if not args.no_fault:
            time.sleep(min(1.0, args.seconds / 4))
            cb.ampctl("debug hang")
            cb.wait_servod_log("recovery complete")
            _say("firmware hung on purpose: servod detected it, the firmware restarted through remoteproc "
                 "(its recovery, or servod's own stop and start where the driver has no report_crash)")
        th.join()
        b.close()
        res = box["r"]
        stats = cb.stats()
        if args.program:
            st = cb.ampctl("status", expected_rc=None)
            state = next((ln for ln in st.splitlines() if ln.startswith("program.state=")), "")
            _say(f"program {state}: path error max {stats.get('motion.path_err.max_um')} um, "
                 f"rms {stats.get('motion.path_err.rms_um')} um; following error max "
                 f"{stats.get('motion.follow_err.max_um')} um")
            if args.can:
                _say("drives: " + " ".join(ln for ln in st.split() if ln.startswith("axis")))
    _say(f"recorded {res.cycles} cycles, {res.messages} messages, {len(res.gaps)} gap(s); "
         f"servod: cycles {stats.get('linux.cycles')}, telemetry pushed "
         f"{stats.get('telem.pushed')}, dropped {stats.get('telem.dropped')}, "
         f"client_lost {stats.get('telem.client_lost')}")
    if res.can_frames:
        _say("recorded CAN frames: " + ", ".join(f"/servoamp/can{k} {n}" for k, n in sorted(res.can_frames.items()))
             + f" (on the cycles' clock, offset {b.clock.offset_ns} ns from the emulator's)"
             + "".join(f"; {e}" for e in b.can_errors.values()))
    # the loggers' files are whole once QEMU has quit (BYE)
    for bus, path in asc.items():
        _say(canload.describe(f"bus load can{bus} ({path})", canload.cycle_load(canload.read_log(path), 1_000_000),
                              1_000_000))
    files = plot.plot(mcap, out / "plots")
    print(info.format_text(info.summarize(mcap)), flush=True)
    _say(f"recording: {mcap} ({mcap.stat().st_size // 1024} KiB; open it in Foxglove with "
         f"tools/foxglove/servoamp-layout.json)")
    for f in files:
        _say(f"plot: {f}")
    _say(f"done in {time.monotonic() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
