"""The demo's last step: the emulated controller live in Foxglove and into MCAP.

    python -m servoamp.demo_record [--seconds N] [--out build/demo] [--keep-logs] [--program]
                                   [--ws-port 8765]

Boots the emulated board with networking (gem0 on QEMU user networking,
host 127.0.0.1:PORT -> guest 7700, see servoamp.netboard), starts servod and
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
then left out (it would end the program) and the recording lasts at least
9 s.
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from pathlib import Path

from servoamp import info, netboard, plot, qemu
from servoamp.bridge import Bridge
from servoamp.record import RecordResult


PROGRAM = "/usr/share/servoamp/examples/seed004_squares_circles.nc"


def _say(msg: str) -> None:
    print(f"[demo-record] {msg}", flush=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m servoamp.demo_record", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
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
    args = ap.parse_args(argv)
    if args.program:
        args.no_fault = True
        args.seconds = max(args.seconds, 9.0)

    t0 = time.monotonic()
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    mcap = out / "run.mcap"
    board = qemu.Board.load("zynq7000_qemu")
    images = qemu.prepare_images(board)
    _say(f"images ready ({time.monotonic() - t0:.1f} s)")
    cb = netboard.ControllerBoard(board, images, host_port=args.port or None,
                                  keep_logs=args.keep_logs)
    with cb:
        _say(f"booted with gem0 on QEMU user networking: 127.0.0.1:{cb.host_port} -> "
             f"guest {netboard.GUEST_ADDR.split('/')[0]}:{netboard.TELEMETRY_PORT} "
             f"({time.monotonic() - t0:.1f} s)")
        cb.start_servod()
        cb.start_firmware()
        hello = cb.wait_telemetry()
        _say(f"servod telemetry: controller {hello.controller_id}, {hello.n_axes} axes, "
             f"period {hello.cycle_period_ns / 1e3:.0f} us")
        # a 10-cycle watchdog trips on TCG hiccups: 50 cycles, and leave SAFESTOP
        cb.ampctl("param set wd_limit 50")
        cb.ampctl("resume", expected_rc=None)

        try:
            b = Bridge("127.0.0.1", cb.host_port, token=cb.token, ws_port=args.ws_port, mcap=mcap)
        except RuntimeError:  # the port is taken
            b = Bridge("127.0.0.1", cb.host_port, token=cb.token, ws_port=0, mcap=mcap)
        box: dict[str, RecordResult] = {}
        th = threading.Thread(target=lambda: box.update(r=b.run(args.seconds)))
        _say(f"live in Foxglove: {b.ws_url} (Open connection > Foxglove WebSocket; layout "
             f"tools/foxglove/servoamp-layout.json) for {args.seconds:g} s (host time)")
        _say(f"recording through the Foxglove SDK into {mcap}")
        th.start()
        time.sleep(min(1.5, args.seconds / 3))
        v = b.set_param("pos_kp", 70.0)
        _say(f"bridge: param set pos_kp 70 -> servod took {v:g}; ampctl param get: "
             + cb.ampctl("param get pos_kp").strip())
        if args.program:
            _say("ampctl run: " + cb.ampctl(f"run {PROGRAM}").strip())
        if not args.no_fault:
            time.sleep(min(1.0, args.seconds / 4))
            cb.ampctl("debug hang")
            cb.wait_servod_log("recovery complete")
            _say("firmware hung on purpose: servod detected it, remoteproc recovered it")
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
    _say(f"recorded {res.cycles} cycles, {res.messages} messages, {len(res.gaps)} gap(s); "
         f"servod: cycles {stats.get('linux.cycles')}, telemetry pushed "
         f"{stats.get('telem.pushed')}, dropped {stats.get('telem.dropped')}, "
         f"client_lost {stats.get('telem.client_lost')}")
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
