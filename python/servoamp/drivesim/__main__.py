# SPDX-License-Identifier: MIT
"""servoamp-drivesim: N CiA 402 drives on one emulated CAN bus, as one
ACTIVE canlink client (docs/fieldbus.md, docs/canlink.md).

    servoamp-drivesim --socket build/can0.sock --nodes 1,2 [--eds FILE]
                      [--fault NODE:KIND@T_S ...]

One loop: read a frame, hand it to every drive with its guest time, send
their answers, then DONE. No host timers: what the drives do depends only
on the frames and their guest times, so a run is repeatable.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

from servoamp import canlink
from servoamp.drivesim.drive import EDS, Drive, Frame, Injection


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


def serve(link: canlink.Link, drives: list[Drive]) -> int:
    """The loop: until QEMU says BYE or closes the socket. Returns the
    number of frames handled."""
    log = logging.getLogger("servoamp.drivesim")
    handled = 0
    log.info("connected: %d bit/s, guest time %.6f s, nodes %s", link.bitrate,
             link.t_hello_ns / 1e9, ",".join(str(d.node_id) for d in drives))
    for d in drives:
        send(link, d.boot(link.t_hello_ns))
    while True:
        try:
            rec = link.recv(None)
        except canlink.ProtocolError as exc:
            if link.closed:
                log.info("QEMU closed the link: %s", exc)
                return handled
            raise
        if rec is None or rec.type == canlink.BYE:
            log.info("QEMU said BYE")
            return handled
        answers: list[Frame] = []
        for d in drives:
            answers += d.on_frame(rec.can_id, rec.data, rec.t_ns, rtr=rec.rtr, eff=rec.eff)
        send(link, answers)
        if not rec.info:
            link.done(rec.seq)
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
    ap.add_argument("--wait", type=float, default=10.0,
                    help="seconds to wait for the socket to appear (default 10)")
    ap.add_argument("-v", "--verbose", action="store_true", help="log state changes and faults")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="drivesim: %(message)s", stream=sys.stderr)
    try:
        nodes = parse_nodes(args.nodes)
        faults = [Injection.parse(f) for f in args.fault]
    except ValueError as exc:
        ap.error(str(exc))
    unknown = sorted({f.node for f in faults} - set(nodes))
    if unknown:
        ap.error(f"--fault for node(s) not simulated: {unknown}")
    drives = [Drive(n, args.eds, faults) for n in nodes]
    try:
        link = connect(args.socket, args.wait)
    except (OSError, canlink.ProtocolError) as exc:
        print(f"servoamp-drivesim: {args.socket}: {exc}", file=sys.stderr)
        return 1
    with link:
        n = serve(link, drives)
    logging.getLogger("servoamp.drivesim").info("%d frames handled", n)
    return 0


if __name__ == "__main__":
    sys.exit(main())
