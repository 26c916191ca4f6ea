"""servoamp command-line entry point (host side).

    servoamp record --connect HOST:PORT -o FILE.mcap [--duration S] [--token-file F]
    servoamp bridge --connect HOST:PORT [--listen 127.0.0.1:8765] [--mcap FILE.mcap] [--token-file F]
                    [--ws-token-file F] [--allow-origin ORIGIN] [--keep-live]
    servoamp plot FILE.mcap -o DIR [--queues CSV]
    servoamp info FILE.mcap [--json]
"""

from __future__ import annotations

import argparse
import json
import logging
import signal
import sys
import threading
from pathlib import Path
from types import FrameType


def _hostport(s: str) -> tuple[str, int]:
    host, sep, port = s.rpartition(":")
    if not sep or not port.isdigit():
        raise argparse.ArgumentTypeError(f"expected HOST:PORT, got {s!r}")
    return host.strip("[]") or "127.0.0.1", int(port)


def _can_link(s: str) -> tuple[int, str]:
    bus, eq, path = s.partition("=")
    if not eq or not bus.isdigit() or not path:
        raise argparse.ArgumentTypeError(f"expected BUS=SOCKET (0=build/can0.sock), got {s!r}")
    return int(bus), path


def _cmd_record(args: argparse.Namespace) -> int:
    from servoamp.record import record
    from servoamp.telemetry import read_token as tw_read_token

    stop = threading.Event()
    # bad frames and the like: one line each on stderr, no traceback
    logging.basicConfig(level=logging.WARNING, stream=sys.stderr,
                        format="servoamp record: %(message)s")

    def on_signal(signum: int, _frame: FrameType | None) -> None:
        stop.set()

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    host, port = args.connect
    token = None
    if args.token_file:
        try:
            token = tw_read_token(args.token_file)
        except OSError as e:
            print(f"servoamp record: --token-file: {e}", file=sys.stderr)
            return 2
    elif args.token:
        token = args.token.encode()
    try:
        res = record(host, port, args.output, args.duration, reconnect=not args.no_reconnect,
                     stop=stop, connect_timeout=args.connect_timeout,
                     flush_interval=args.flush_interval, flush_messages=args.flush_messages,
                     compression=args.compression, token=token)
    except ConnectionError as e:
        print(f"servoamp record: {e}", file=sys.stderr)
        return 3
    except OSError as e:  # the output file
        print(f"servoamp record: {args.output}: {e}", file=sys.stderr)
        return 2
    if res.bad_frames:
        by = ", ".join(f"{k} {v}" for k, v in sorted(res.bad_frames_by_type.items()))
        print(f"servoamp record: {res.bad_frames} bad frames skipped ({by}); "
              f"counted in the file's servoamp.recording metadata", file=sys.stderr)
    if stop.is_set():
        res.stopped_by = "signal"
    d = res.as_dict()
    d["cycles_per_cpu_s"] = round(res.cycles / res.cpu_s) if res.cpu_s > 0 else None
    if args.json:
        print(json.dumps(d))
    else:
        print(f"recorded {res.cycles} cycles ({res.messages} messages, {len(res.gaps)} gaps, "
              f"{res.connections} connections) into {res.path} in {res.wall_s:.1f} s "
              f"(CPU {res.cpu_s:.2f} s); stopped by {res.stopped_by}")
    return 0


def _token(args: argparse.Namespace, prog: str) -> tuple[bytes | None, int]:
    from servoamp.telemetry import read_token as tw_read_token

    if args.token_file:
        try:
            return tw_read_token(args.token_file), 0
        except OSError as e:
            print(f"servoamp {prog}: --token-file: {e}", file=sys.stderr)
            return None, 2
    return (args.token.encode() if args.token else None), 0


def _cmd_bridge(args: argparse.Namespace) -> int:
    from servoamp.bridge import Bridge, RecordingError
    from servoamp.wsfront import DEFAULT_ORIGINS

    stop = threading.Event()

    def on_signal(signum: int, _frame: FrameType | None) -> None:
        stop.set()

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    token, rc = _token(args, "bridge")
    if rc:
        return rc
    if args.no_telemetry and not args.can:
        print("servoamp bridge: --no-telemetry carries CAN frames only: give --can", file=sys.stderr)
        return 2
    if not args.no_telemetry and args.connect is None:
        print("servoamp bridge: --connect HOST:PORT (servod's telemetry) is required, "
              "unless --no-telemetry", file=sys.stderr)
        return 2
    host, port = args.connect or ("127.0.0.1", 0)
    ws_host, ws_port = args.listen
    ws_token = None
    if args.ws_token_file:
        try:
            ws_token = Path(args.ws_token_file).read_text().strip()
        except OSError as e:
            print(f"servoamp bridge: --ws-token-file: {e}", file=sys.stderr)
            return 2
        if len(ws_token) < 16 or not all(c.isalnum() or c in "-_" for c in ws_token):
            print("servoamp bridge: --ws-token-file: the token must be at least 16 characters "
                  "of A-Z a-z 0-9 - _", file=sys.stderr)
            return 2
    try:
        b = Bridge(host, port, token=token, ws_host=ws_host, ws_port=ws_port,
                   serve=not args.no_server, mcap=args.mcap, reconnect=not args.no_reconnect,
                   connect_timeout=args.connect_timeout, params=not args.no_params,
                   ws_token=ws_token, allow_origins=[*DEFAULT_ORIGINS, *args.allow_origin],
                   flush_interval=args.flush_interval, keep_live=args.keep_live,
                   can_links=dict(args.can), telemetry=not args.no_telemetry)
    except (OSError, RuntimeError, ValueError) as e:
        print(f"servoamp bridge: {e}", file=sys.stderr)
        return 4
    url = b.ws_url
    rc = 0
    try:
        if url:
            print(f"servoamp bridge: Foxglove WebSocket on {url} "
                  f"(Foxglove: Open connection > Foxglove WebSocket; the token gives the right "
                  f"to set parameters, {b.ws_url_plain} is read-only)", flush=True)
        if args.mcap:
            print(f"servoamp bridge: recording to {args.mcap}", flush=True)
        try:
            res = b.run(args.duration, stop)
        except ConnectionError as e:
            print(f"servoamp bridge: {e}", file=sys.stderr)
            return 3
        except RecordingError as e:
            print(f"servoamp bridge: {e}", file=sys.stderr)
            res = b.res
            res.stopped_by = "record_error"
            rc = 5
        if stop.is_set():
            res.stopped_by = "signal"
    finally:
        b.close()
    if b.record_error and rc == 0:
        print(f"servoamp bridge: {b.record_error}", file=sys.stderr)
        rc = 5
    d = res.as_dict()
    d["ws_url"] = url
    d["record_error"] = b.record_error
    if args.json:
        print(json.dumps(d))
    else:
        print(f"bridged {res.cycles} cycles ({res.messages} messages, {len(res.gaps)} gaps, "
              f"{res.connections} connections) in {res.wall_s:.1f} s (CPU {res.cpu_s:.2f} s); "
              f"stopped by {res.stopped_by}")
    return rc


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="servoamp", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="store_true", help="print the version")
    sub = parser.add_subparsers(dest="cmd")

    p = sub.add_parser("record", help="record the telemetry stream into an MCAP file")
    p.add_argument("--connect", type=_hostport, required=True, metavar="HOST:PORT")
    p.add_argument("-o", "--output", required=True, metavar="FILE.mcap")
    p.add_argument("--duration", type=float, default=None, metavar="S",
                   help="stop after S seconds (default: until SIGINT/SIGTERM)")
    p.add_argument("--no-reconnect", action="store_true",
                   help="stop when the stream ends instead of reconnecting")
    p.add_argument("--connect-timeout", type=float, default=10.0, metavar="S",
                   help="without --duration: give up when no first connection in S seconds")
    p.add_argument("--flush-interval", type=float, default=1.0, metavar="S",
                   help="close a chunk at least every S seconds of controller time and of "
                        "host time (bounds what SIGKILL loses)")
    p.add_argument("--flush-messages", type=int, default=10_000, metavar="N",
                   help="close a chunk at least every N messages")
    p.add_argument("--compression", choices=["zstd", "lz4", "none"], default="zstd")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    tok = p.add_mutually_exclusive_group()
    tok.add_argument("--token", metavar="TOKEN",
                     help="the shared token servod was given (--telemetry-token); "
                          "visible in the process list: prefer --token-file")
    tok.add_argument("--token-file", metavar="FILE", help="read the token from FILE")

    p = sub.add_parser("bridge", help="serve the telemetry to Foxglove (WebSocket) and "
                                      "record it (MCAP) through the Foxglove SDK")
    p.add_argument("--connect", type=_hostport, metavar="HOST:PORT",
                   help="servod's telemetry (required unless --no-telemetry)")
    p.add_argument("--no-telemetry", action="store_true",
                   help="no servod (a machine without Linux): carry only the --can buses, "
                        "their frames logged on the emulator's virtual time; ends when QEMU "
                        "has closed every bus")
    p.add_argument("--listen", type=_hostport, default=("127.0.0.1", 8765), metavar="HOST:PORT",
                   help="the Foxglove WebSocket server's address (default 127.0.0.1:8765; "
                        "port 0: any free port)")
    p.add_argument("--no-server", action="store_true", help="MCAP only, no WebSocket server")
    p.add_argument("--no-params", action="store_true",
                   help="do not offer the parameters capability at all")
    p.add_argument("--ws-token-file", metavar="FILE",
                   help="the token of the URL that may set parameters (default: a new random "
                        "one, printed in the URL)")
    p.add_argument("--allow-origin", action="append", default=[], metavar="ORIGIN",
                   help="also let web pages of ORIGIN (scheme://host[:port], ':*' for any "
                        "port) connect read-only; by default the Foxglove app and pages of "
                        "localhost, 127.0.0.1 and [::1]")
    p.add_argument("--flush-interval", type=float, default=1.0, metavar="S",
                   help="hand the recording to the OS at least every S s (SIGKILL loses at "
                        "most that; default 1)")
    p.add_argument("--keep-live", action="store_true",
                   help="when the recording cannot be written (a full disk), go on serving "
                        "the live view instead of stopping (exit 5)")
    p.add_argument("--mcap", metavar="FILE.mcap", help="also write the channels to FILE")
    p.add_argument("--can", type=_can_link, action="append", default=[], metavar="BUS=SOCKET",
                   help="also carry every frame of emulated CAN bus BUS (its canlink socket, "
                        "docs/canlink.md) on /servoamp/canBUS; repeat per bus")
    p.add_argument("--duration", type=float, default=None, metavar="S",
                   help="stop after S seconds (default: until SIGINT/SIGTERM)")
    p.add_argument("--no-reconnect", action="store_true",
                   help="stop when the stream ends instead of reconnecting")
    p.add_argument("--connect-timeout", type=float, default=10.0, metavar="S")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    tok = p.add_mutually_exclusive_group()
    tok.add_argument("--token", metavar="TOKEN", help="servod's --telemetry-token (prefer "
                                                      "--token-file); setting parameters needs it")
    tok.add_argument("--token-file", metavar="FILE", help="read the token from FILE")

    p = sub.add_parser("plot", help="PNG figures from a recording")
    p.add_argument("file")
    p.add_argument("-o", "--output", required=True, metavar="DIR")
    p.add_argument("--queues", metavar="CSV", help="queue levels from motion_cli --trace")

    p = sub.add_parser("info", help="summary of a recording")
    p.add_argument("file")
    p.add_argument("--json", action="store_true")

    args = parser.parse_args(argv)
    if args.version:
        from servoamp import __version__

        print(__version__)
        return 0
    if args.cmd == "record":
        return _cmd_record(args)
    if args.cmd == "bridge":
        return _cmd_bridge(args)
    if args.cmd == "plot":
        from servoamp.plot import plot

        for f in plot(args.file, args.output, args.queues):
            print(f)
        return 0
    if args.cmd == "info":
        from servoamp.info import main_info

        return main_info(args.file, args.json)
    parser.print_help()
    return 0


if __name__ == "__main__":
    sys.exit(main())
