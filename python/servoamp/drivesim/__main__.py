# SPDX-License-Identifier: MIT
"""servoamp-drivesim: N CiA 402 drives on one emulated CAN bus, as one
ACTIVE canlink client (docs/fieldbus.md, docs/canlink.md).

    servoamp-drivesim --socket build/can0.sock --nodes 1,2 [--eds FILE]
                      [--fault NODE:KIND@T_S ...] [--bus-short T_S:MS ...]
                      [--fault-reset-cycles [NODE:]N|never ...]

One loop: read a frame, hand it to every drive with its guest time, send
their answers, then DONE. No host timers: what the drives do depends only
on the frames and their guest times, so a run is repeatable.

A bus short (``--bus-short``, or ``bus-short MS`` on the control socket)
destroys every frame on the bus for MS ms of guest time: each guest frame
is ended with DONE ERROR (a bus error: the controller counts it and
retransmits, so it goes error passive and bus off), the drives see none
and send nothing, their heartbeats stop with them.
"""

from __future__ import annotations

import argparse
import logging
import os
import socket
import sys
import time
from pathlib import Path

from servoamp import canlink
from servoamp.drivesim.drive import EDS, FAULT_ALIASES, Drive, Frame, Injection, parse_reset_cycles

# exit statuses (docs/fieldbus.md)
EXIT_BYE = 0            # QEMU said BYE (it does when it quits)
EXIT_CONNECT = 1        # no canlink connection (no socket, no HELLO)
EXIT_USAGE = 2          # bad options (argparse)
EXIT_LINK_LOST = 3      # QEMU dropped the simulator: the socket closed without BYE, reset, or a bad record

# the control socket: connections read without waiting, at most this many,
# each closed when it has sent no whole request line for this long
CONTROL_MAX_CONNECTIONS = 8
CONTROL_IDLE_S = 5.0
CONTROL_LINE_MAX = 256


class LinkLost(Exception):
    """The canlink connection ended without BYE; the message says how, in
    one line."""


def parse_nodes(text: str) -> list[int]:
    nodes: list[int] = []
    for part in text.split(","):
        part = part.strip()
        if "-" in part:
            lo, hi = (int(x, 0) for x in part.split("-", 1))
            nodes += range(lo, hi + 1)
        elif part:
            nodes.append(int(part, 0))
    if not nodes or any(not 1 <= n <= 127 for n in nodes) or len(set(nodes)) != len(nodes):
        raise ValueError(f"nodes {text!r}: distinct node ids in 1..127")
    return nodes


def connect(path: str, wait_s: float) -> canlink.Link:
    """Connect as an active client, retrying while the socket does not
    exist yet (QEMU starting), up to ``wait_s`` seconds."""
    deadline = time.monotonic() + wait_s
    while True:
        try:
            return canlink.Link.connect(path, active=True, name="drivesim")
        except (FileNotFoundError, ConnectionRefusedError):
            if time.monotonic() >= deadline:
                raise
            time.sleep(0.05)


def send(link: canlink.Link, frames: list[Frame]) -> None:
    for f in frames:
        link.send_frame(f.can_id, f.data, t_ns=f.t_ns)


class BusShort:
    """When the bus is shorted, in guest time (the frames' bus end times).
    A short asked for "now" starts at the next frame."""

    def __init__(self, windows: list[tuple[int, int]] | None = None) -> None:
        self.windows = sorted(windows or [])          # (start ns, end ns)
        self.next_ms: int | None = None
        self.frames_destroyed = 0

    @staticmethod
    def parse(text: str) -> tuple[int, int]:
        """``T_S:MS``, e.g. ``2.5:20``: from 2.5 s of guest time, 20 ms."""
        try:
            at, ms = text.split(":", 1)
            start = round(float(at) * 1e9)
            dur = round(float(ms) * 1e6)
        except ValueError:
            raise ValueError(f"--bus-short {text!r}: expected T_S:MS, e.g. 2.5:20") from None
        if start < 0 or dur <= 0:
            raise ValueError(f"--bus-short {text!r}: the time must be >= 0 and the length > 0")
        return start, start + dur

    def request(self, ms: int) -> None:
        self.next_ms = ms

    def shorted(self, t_ns: int) -> bool:
        if self.next_ms is not None:
            self.windows.append((t_ns, t_ns + self.next_ms * 1_000_000))
            self.windows.sort()
            logging.getLogger("servoamp.drivesim").info(
                "bus shorted from %.6f s for %d ms", t_ns / 1e9, self.next_ms)
            self.next_ms = None
        while self.windows and self.windows[0][1] <= t_ns:
            self.windows.pop(0)
        return bool(self.windows) and self.windows[0][0] <= t_ns


class Control:
    """``--control PATH``: a Unix socket taking one request line per
    connection, answered with one line, then closed:

    - ``fault NODE KIND``: inject KIND (following-error, over-current,
      off-bus) into drive NODE with the next frame on the bus (its guest
      time is the fault's; ``-v`` logs it);
    - ``bus-short MS``: short the bus for MS ms of guest time from the
      next frame (every frame destroyed by a bus error, see BusShort);
    - ``fault-reset NODE CYCLES|never``: the SYNCs drive NODE needs to
      leave Fault after a fault reset from now on (Drive.fault_reset_cycles);
    - ``state``: each drive's node id, CiA 402 state, NMT state, off-bus,
      fault reset cycles.

    Polled once per frame, so it acts only while the bus carries traffic
    (the master's SYNC every cycle). A poll never waits: it takes what the
    connections sent so far, answers the whole lines, and closes a
    connection that sent none in CONTROL_IDLE_S (and the oldest when more
    than CONTROL_MAX_CONNECTIONS are open), so a silent client costs the
    lockstep loop nothing."""

    def __init__(self, path: str, drives: list[Drive], short: BusShort | None = None) -> None:
        if os.path.exists(path):
            os.unlink(path)
        self.path = path
        self.drives = {d.node_id: d for d in drives}
        self.short = short if short is not None else BusShort()
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self.sock.bind(path)
        self.sock.listen(CONTROL_MAX_CONNECTIONS)
        self.sock.setblocking(False)
        self.conns: dict[socket.socket, tuple[bytearray, float]] = {}   # request so far, since

    def answer(self, line: str) -> str:
        words = line.split()
        if len(words) == 3 and words[0] == "fault":
            try:
                node = int(words[1], 0)
            except ValueError:
                return f"error: node {words[1]!r} is not a number"
            kind = FAULT_ALIASES.get(words[2].lower())
            if node not in self.drives:
                return f"error: no drive {node} (drives {sorted(self.drives)})"
            if kind is None:
                return f"error: fault kind {words[2]!r} unknown"
            self.drives[node].inject(kind)
            return f"ok fault {node} {kind.value}"
        if len(words) == 2 and words[0] == "bus-short":
            try:
                ms = int(words[1], 0)
            except ValueError:
                return f"error: bus-short {words[1]!r}: not a whole number of ms"
            if not 1 <= ms <= 60_000:
                return f"error: bus-short {ms}: 1..60000 ms"
            self.short.request(ms)
            return f"ok bus-short {ms}"
        if len(words) == 3 and words[0] == "fault-reset":
            try:
                rnode, cycles = parse_reset_cycles(f"{words[1]}:{words[2]}")
            except ValueError as exc:
                return f"error: {exc}"
            if rnode is None or rnode not in self.drives:
                return f"error: no drive {rnode} (drives {sorted(self.drives)})"
            self.drives[rnode].fault_reset_cycles = cycles
            return f"ok fault-reset {rnode} {'never' if cycles is None else cycles}"
        if words == ["state"]:
            return "ok " + "; ".join(
                f"{n}: {d.state.name} nmt={d.nmt.name} off_bus={int(d.off_bus)} "
                f"fault_reset={'never' if d.fault_reset_cycles is None else d.fault_reset_cycles}"
                for n, d in sorted(self.drives.items()))
        return "error: requests are 'fault NODE KIND', 'bus-short MS', 'fault-reset NODE CYCLES|never' and 'state'"

    def poll(self) -> None:
        now = time.monotonic()
        while True:
            try:
                conn, _ = self.sock.accept()
            except OSError:                    # none waiting (or no file descriptor left)
                break
            conn.setblocking(False)
            if len(self.conns) >= CONTROL_MAX_CONNECTIONS:
                self._drop(min(self.conns, key=lambda c: self.conns[c][1]))
            self.conns[conn] = (bytearray(), now)
        for conn, (req, since) in list(self.conns.items()):
            try:
                chunk = conn.recv(CONTROL_LINE_MAX)
            except (BlockingIOError, InterruptedError):
                if now - since > CONTROL_IDLE_S:
                    self._drop(conn)
                continue
            except OSError:
                self._drop(conn)
                continue
            req += chunk
            if not chunk and not req:
                self._drop(conn)               # closed without a request
            elif not chunk or b"\n" in req or len(req) >= CONTROL_LINE_MAX:
                line = bytes(req).split(b"\n", 1)[0][:CONTROL_LINE_MAX]
                try:
                    conn.send((self.answer(line.decode("ascii", "replace").strip()) + "\n").encode())
                except OSError:
                    pass                       # gone, or not reading: its loss
                self._drop(conn)

    def _drop(self, conn: socket.socket) -> None:
        del self.conns[conn]
        conn.close()

    def close(self) -> None:
        for conn in list(self.conns):
            self._drop(conn)
        self.sock.close()
        try:
            os.unlink(self.path)
        except OSError:
            pass


def control_request(path: str | Path, line: str, timeout: float = 10.0) -> str:
    """One request to a running simulator's --control socket; its answer."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.settimeout(timeout)
        s.connect(str(path))
        s.sendall(line.encode("ascii") + b"\n")
        buf = b""
        while not buf.endswith(b"\n"):
            chunk = s.recv(4096)
            if not chunk:
                break
            buf += chunk
    return buf.decode("ascii", "replace").strip()


def _recv(link: canlink.Link) -> canlink.Record | None:
    """The next record from QEMU; LinkLost if the link is gone."""
    try:
        return link.recv(None)
    except canlink.ProtocolError as exc:
        if link.closed:
            raise LinkLost("QEMU closed the link without BYE: it dropped this client (QEMU's log "
                           "says why) or it died") from None
        raise LinkLost(f"bad record from QEMU: {exc}") from None
    except OSError as exc:
        raise LinkLost(f"QEMU dropped the link: {exc.strerror or exc}") from None


def _lost_while_sending(link: canlink.Link, what: str, exc: OSError) -> LinkLost | None:
    """A write failed: None if QEMU said BYE before it went (a normal
    end), else the LinkLost to raise."""
    try:
        while (rec := link.recv(0)) is not None:
            if rec.type == canlink.BYE:
                return None
    except (canlink.ProtocolError, OSError):
        pass
    return LinkLost(f"QEMU dropped the link while the simulator sent {what}: {exc.strerror or exc}")


def serve(link: canlink.Link, drives: list[Drive], control: Control | None = None,
          short: BusShort | None = None) -> int:
    """The loop: until QEMU says BYE. Returns the number of frames handled;
    LinkLost when QEMU drops the link (closes it without BYE, resets it)
    or sends a bad record."""
    log = logging.getLogger("servoamp.drivesim")
    handled = 0
    if short is None:
        short = control.short if control is not None else BusShort()
    log.info("connected: %d bit/s, guest time %.6f s, nodes %s", link.bitrate,
             link.t_hello_ns / 1e9, ",".join(str(d.node_id) for d in drives))
    try:
        for d in drives:
            send(link, d.boot(link.t_hello_ns))
    except OSError as exc:
        lost = _lost_while_sending(link, "the boot-ups", exc)
        if lost is None:
            return handled
        raise lost from None
    while True:
        rec = _recv(link)
        if rec is None or rec.type == canlink.BYE:
            log.info("QEMU said BYE")
            return handled
        if rec.type == canlink.ERROR:
            continue                    # a frame destroyed (by us or another client)
        if control is not None:
            control.poll()
        try:
            if short.shorted(rec.t_ns):
                if not rec.info:
                    short.frames_destroyed += 1
                    link.done(rec.seq, error=True)
                handled += 1
                continue
            answers: list[Frame] = []
            for d in drives:
                answers += d.on_frame(rec.can_id, rec.data, rec.t_ns, rtr=rec.rtr, eff=rec.eff)
            send(link, answers)
            if not rec.info:
                link.done(rec.seq)
        except OSError as exc:
            lost = _lost_while_sending(link, f"the answers to frame {rec.seq}", exc)
            if lost is None:
                log.info("QEMU said BYE")
                return handled
            raise lost from None
        handled += 1


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="servoamp-drivesim", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--socket", required=True, help="canlink socket of QEMU's can-host-lockstep")
    ap.add_argument("--nodes", default="1", help="node ids, e.g. 1,2 or 1-4 (default 1)")
    ap.add_argument("--eds", type=Path, default=EDS, help=f"object dictionary (default {EDS.name})")
    ap.add_argument("--fault", action="append", default=[], metavar="NODE:KIND@T_S",
                    help="inject a fault: KIND following-error | over-current | off-bus, "
                         "at guest time T_S seconds (repeatable)")
    ap.add_argument("--bus-short", action="append", default=[], metavar="T_S:MS",
                    help="short the bus from T_S s of guest time for MS ms: every frame destroyed "
                    "by a bus error (the controller goes bus off)")
    ap.add_argument("--fault-reset-cycles", action="append", default=[], metavar="[NODE:]N|never",
                    help="SYNCs a drive needs to leave Fault after a fault reset, bit 7 held (default 0: "
                    "at once; never: the fault does not clear); without NODE every drive (repeatable)")
    ap.add_argument("--wait", type=float, default=10.0,
                    help="seconds to wait for the socket to appear (default 10)")
    ap.add_argument("--control", metavar="PATH",
                    help="Unix socket for requests while running: 'fault NODE KIND', 'bus-short MS', "
                    "'state'")
    ap.add_argument("-v", "--verbose", action="store_true", help="log state changes and faults")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="drivesim: %(message)s", stream=sys.stderr)
    try:
        nodes = parse_nodes(args.nodes)
        faults = [Injection.parse(f) for f in args.fault]
        short = BusShort([BusShort.parse(t) for t in args.bus_short])
        resets = [parse_reset_cycles(t) for t in args.fault_reset_cycles]
    except ValueError as exc:
        ap.error(str(exc))
    unknown = sorted({f.node for f in faults} - set(nodes))
    if unknown:
        ap.error(f"--fault for node(s) not simulated: {unknown}")
    unknown = sorted({n for n, _ in resets if n is not None} - set(nodes))
    if unknown:
        ap.error(f"--fault-reset-cycles for node(s) not simulated: {unknown}")
    reset_of: dict[int, int | None] = {}
    for node, cycles in resets:            # in order: a later one wins
        for n in nodes if node is None else [node]:
            reset_of[n] = cycles
    drives = [Drive(n, args.eds, faults, reset_of.get(n, 0)) for n in nodes]
    try:
        link = connect(args.socket, args.wait)
    except (OSError, canlink.ProtocolError) as exc:
        print(f"servoamp-drivesim: {args.socket}: {exc}", file=sys.stderr)
        return EXIT_CONNECT
    control = Control(args.control, drives, short) if args.control else None
    try:
        with link:
            n = serve(link, drives, control, short)
    except LinkLost as exc:
        print(f"servoamp-drivesim: {args.socket}: {exc}", file=sys.stderr)
        return EXIT_LINK_LOST
    finally:
        if control is not None:
            control.close()
    logging.getLogger("servoamp.drivesim").info("%d frames handled", n)
    return EXIT_BYE


if __name__ == "__main__":
    sys.exit(main())
