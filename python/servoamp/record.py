"""Record the telemetry stream of a controller into an MCAP file.

    from servoamp.record import record
    res = record("127.0.0.1", 7700, "run.mcap", duration=10.0)

The loop decodes the stream with precompiled structs and writes each
message with the mcap writer from preformatted JSON templates; see
docs/recording.md for the channels, the reconnect behaviour and what a
killed recorder leaves behind.
"""

from __future__ import annotations

import json
import logging
import socket
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from mcap.writer import CompressionType

from servoamp import mcapio
from servoamp import telemetry as tw

_CYCLE_T = (b'{"cycle":%d,"servo_cycle":%d,"t_cycle":%d,"irq_latency_ticks":%d,'
            b'"irq_latency_ns":%.1f,"wake_latency_ns":%d,"exchange":"%s","exchange_code":%d,'
            b'"missed":%d,"servo_status":%d,"result":%d}')
_AXIS_T = (b'{"cycle":%d,"axis":%d,"command":{"control_word":%d,"target_pos":%d,"vel_ff":%d,'
           b'"torque_offset":%d},"feedback":{"status_word":%d,"actual_pos":%d,"actual_vel":%d,'
           b'"current":%d,"following_error":%d}}')
_PATH_T = b'{"cycle":%d,"command":{"x":%d,"y":%d},"actual":{"x":%d,"y":%d}}'
_EXN = [n.encode() for n in tw.EXCHANGE_NAMES]

log = logging.getLogger("servoamp.record")
BAD_FRAMES_SHOWN = 20  # bad frames reported one by one; the rest are only counted


@dataclass
class RecordResult:
    path: str
    cycles: int = 0
    messages: int = 0
    connections: int = 0
    gaps: list[dict[str, Any]] = field(default_factory=list)
    first_cycle: int | None = None
    last_cycle: int | None = None
    stopped_by: str = ""
    wall_s: float = 0.0
    cpu_s: float = 0.0
    last_stats: dict[str, Any] | None = None
    controller_id: str = ""
    bad_frames: int = 0
    bad_frames_by_type: dict[str, int] = field(default_factory=dict)
    flushes: int = 0
    # servoamp bridge with CAN links: frames recorded per bus
    can_frames: dict[int, int] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


class _Session:
    """State of one recording across connections."""

    def __init__(self, w: mcapio.RecordingWriter, res: RecordResult) -> None:
        self.w = w
        self.res = res
        self.hello: tw.Hello | None = None
        self.cstruct = tw.cycle_struct(1)
        self.n_axes = 0
        self.tick_ns = 1.0
        self.cid_cycle = w.channel(mcapio.T_CYCLE)
        self.cid_axes: list[int] = []
        self.cid_path: int | None = None
        self.last_cycle: int | None = None
        self.last_t_ns = 0
        self.expect: int | None = None
        self.pending_reconnect: tuple[int | None, int | None, bool] | None = None
        self.final_seen = False
        self.meta_written = False
        self.hello_this_conn = False

    def new_connection(self) -> None:
        self.hello_this_conn = False

    def bad_frame(self, typ: int, ln: int, why: str) -> None:
        """A frame that does not decode: counted, reported, skipped."""
        res = self.res
        name = tw.msg_name(typ)
        res.bad_frames += 1
        res.bad_frames_by_type[name] = res.bad_frames_by_type.get(name, 0) + 1
        if res.bad_frames <= BAD_FRAMES_SHOWN:
            log.warning("bad %s frame (%d bytes) after cycle %s skipped: %s", name, ln,
                        self.last_cycle, why)
            if res.bad_frames == BAD_FRAMES_SHOWN:
                log.warning("further bad frames are counted, not shown")

    # -- messages -----------------------------------------------------------------
    def on_hello(self, h: tw.Hello) -> None:
        prev = self.hello
        self.res.connections += 1
        if prev is not None:
            self.pending_reconnect = (self.last_cycle, self.last_t_ns,
                                      prev.session_id != h.session_id)
            self.expect = None  # the first cycle of this connection writes the marker
        self.hello = h
        self.hello_this_conn = True
        self.res.controller_id = h.controller_id
        self.final_seen = False
        if h.n_axes != self.n_axes:
            self.n_axes = h.n_axes
            self.cstruct = tw.cycle_struct(h.n_axes)
            self.cid_axes = [self.w.channel(mcapio.axis_topic(i)) for i in range(h.n_axes)]
            self.cid_path = self.w.channel(mcapio.T_PATH) if h.n_axes >= 2 else None
        self.tick_ns = 1e9 / h.clock_hz if h.clock_hz else 0.0
        self.w.write(mcapio.T_SESSION, h.t_ns, {
            "connection": self.res.connections, "controller_id": h.controller_id,
            "session_id": f"{h.session_id:016x}", "wire_version": h.version,
            "n_axes": h.n_axes, "cycle_period_ns": h.cycle_period_ns, "clock_hz": h.clock_hz,
            "ring_capacity": h.ring_capacity, "realtime_ns": h.realtime_ns})
        if not self.meta_written:
            self.meta_written = True
            self.w.metadata("servoamp", tw.hello_metadata(h))

    def gap(self, t_ns: int, reason: str, source: str, frm: int | None, to: int | None,
            lost: int | None, detail: str) -> None:
        g = {"reason": reason, "source": source, "from_cycle": frm, "to_cycle": to,
             "lost": lost, "detail": detail}
        self.w.write(mcapio.T_GAP, t_ns, g)
        self.res.gaps.append(dict(g, t_ns=t_ns))

    def on_cycle_batch_start(self, cyc: int, t_ns: int) -> None:
        """Continuity checks before the first cycle of a connection or after a hole."""
        pr = self.pending_reconnect
        self.pending_reconnect = None
        g = tw.receiver_gap((pr[0], pr[2]) if pr is not None else None, self.expect, cyc)
        if g is not None:
            self.gap(t_ns, g[0], "recorder", *g[1:])
        if pr is not None or g is not None:
            self.expect = cyc

    def on_gap(self, g: tw.Gap) -> None:
        self.gap(g.t_ns, g.reason, "controller", g.from_cycle, g.to_cycle, g.count,
                 f"announced by the controller ({g.count} records)")
        if g.count and g.reason in ("ring_overflow", "client_overflow"):
            self.expect = g.to_cycle + 1

    def on_stats(self, s: tw.Stats) -> None:
        d = {"last_cycle": s.last_cycle, "pushed": s.pushed, "dropped": s.dropped,
             "drained": s.drained, "client_lost": s.client_lost,
             "client_events_lost": s.client_events_lost, "events": s.events,
             "events_dropped": s.events_dropped, "bytes_sent": s.bytes_sent,
             "ring_high_water": s.ring_high_water, "ring_capacity": s.ring_capacity,
             "clients": s.clients, "final": s.final, "counters": s.counters}
        self.w.write(mcapio.T_STATS, s.t_ns, d)
        self.res.last_stats = d
        if s.final:
            self.final_seen = True

    def process(self, buf: bytearray, frames: Any) -> None:
        """Decode and write the frames; a frame that does not decode is counted
        and skipped (bad_frame). tw.ProtocolError from the frames iterator (the
        framing itself is lost) goes to the caller, after the bookkeeping."""
        w = self.w
        add = w.writer.add_message
        cstruct = self.cstruct
        unpack = cstruct.unpack_from
        csize = cstruct.size
        cid_cycle = self.cid_cycle
        cid_axes = self.cid_axes
        cid_path = self.cid_path
        n = self.n_axes
        tick_ns = self.tick_ns
        cycles = 0
        nmsg = 0
        t_ns = self.last_t_ns
        try:
            for typ, off, ln in frames:
                if typ == tw.MSG_CYCLE:
                    if not self.hello_this_conn:
                        self.bad_frame(typ, ln, "CYCLE before a valid HELLO on this connection")
                        continue
                    if ln < csize:
                        self.bad_frame(typ, ln, f"CYCLE of {ln} bytes, expected {csize} "
                                                f"for {n} axes")
                        continue
                    v = unpack(buf, off)
                    cyc = v[0]
                    t_ns = v[1]
                    if cyc != self.expect:
                        self.on_cycle_batch_start(cyc, t_ns)
                    self.expect = cyc + 1
                    seq = cyc & 0xFFFFFFFF
                    add(cid_cycle, t_ns, _CYCLE_T % (cyc, v[2], v[3], v[4], v[4] * tick_ns, v[5],
                                                     _EXN[v[6]] if v[6] < 6 else b"none", v[6],
                                                     v[7], v[8], v[9]), t_ns, seq)
                    a = 11
                    for i in range(n):
                        add(cid_axes[i], t_ns, _AXIS_T % ((cyc, i) + v[a:a + 9]), t_ns, seq)
                        a += 9
                    if cid_path is not None:
                        add(cid_path, t_ns, _PATH_T % (cyc, v[12], v[21], v[16], v[25]), t_ns,
                            seq)
                        nmsg += 1
                    nmsg += 1 + n
                    cycles += 1
                    if self.res.first_cycle is None:
                        self.res.first_cycle = cyc
                    self.last_cycle = cyc
                    continue
                try:
                    m = tw.decode(typ, bytes(buf[off:off + ln]))
                except tw.ProtocolError as e:
                    self.bad_frame(typ, ln, str(e))
                    continue
                if isinstance(m, tw.Hello):
                    self.on_hello(m)
                    # the axis count may have changed: rebind the locals
                    cstruct = self.cstruct
                    unpack = cstruct.unpack_from
                    csize = cstruct.size
                    cid_axes = self.cid_axes
                    cid_path = self.cid_path
                    n = self.n_axes
                    tick_ns = self.tick_ns
                elif isinstance(m, tw.Stats):
                    self.on_stats(m)
                elif isinstance(m, tw.Param):
                    w.write(mcapio.T_PARAM, m.t_ns, {"cycle": m.cycle, "id": m.id,
                                                     "name": m.name, "type": m.type,
                                                     "value": m.value, "unit": m.unit})
                elif isinstance(m, tw.Log):
                    w.write(mcapio.T_LOG, m.t_ns, {
                        "timestamp": {"sec": m.t_ns // 1_000_000_000,
                                      "nsec": m.t_ns % 1_000_000_000},
                        "level": m.level if 0 <= m.level <= 5 else 0,
                        "message": m.text, "name": m.source, "file": "", "line": 0})
                elif isinstance(m, tw.Gap):
                    self.on_gap(m)
                elif isinstance(m, tw.Queues):
                    w.write(mcapio.T_QUEUES, m.t_ns, {
                        "levels": {k: lv for k, (lv, _c) in m.levels.items()},
                        "capacity": {k: c for k, (_lv, c) in m.levels.items()}})
                # unknown types (None) are skipped: forward compatible
        finally:
            self.last_t_ns = t_ns
            self.res.cycles += cycles
            w.messages += nmsg
            if self.last_cycle is not None:
                self.res.last_cycle = self.last_cycle
            w.maybe_flush(t_ns if cycles else None)


def record(host: str, port: int, out: str | Path, duration: float | None = None, *,
           reconnect: bool = True, stop: threading.Event | None = None,
           connect_timeout: float = 10.0, max_backoff: float = 2.0,
           flush_interval: float = 1.0, flush_messages: int = 10_000,
           chunk_size: int = 1 << 20, compression: str = "zstd",
           on_progress: Callable[[RecordResult], None] | None = None,
           token: bytes | str | None = None) -> RecordResult:
    """Record from host:port into out until duration (s, wall clock) elapses,
    stop is set, or (reconnect=False) the stream ends.

    With reconnect=True a lost connection is retried with exponential backoff
    (0.05 s doubling up to max_backoff) and the hole is written on
    /servoamp/gap. Without a first connection within connect_timeout (when
    no duration is given) ConnectionError is raised. The file is finalized
    (summary, indexes) in every case but SIGKILL.

    A frame that does not decode (short, or a field out of range) is counted
    in res.bad_frames, reported once on the "servoamp.record" logger (the
    first BAD_FRAMES_SHOWN), and skipped. A frame header announcing more than
    FrameSplitter.MAX_FRAME bytes loses the framing: it is counted too, and the
    connection is dropped and re-established (reconnect=True) or the
    recording ends with stopped_by "protocol_error".

    The open chunk is written out every flush_interval seconds (controller
    time, and host time whatever arrives) and every flush_messages messages:
    that bounds what a SIGKILL loses (mcapio.RecordingWriter).

    Every connection starts with an AUTH frame carrying token (servod's
    --telemetry-token; None: an empty token, for a server without one).
    """
    auth = tw.encode_auth(token)
    comp = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4,
            "none": CompressionType.NONE}[compression]
    stop = stop or threading.Event()
    res = RecordResult(path=str(out))
    t0 = time.monotonic()
    c0 = time.process_time()
    deadline = t0 + duration if duration is not None else None
    f = open(out, "wb")
    w = mcapio.RecordingWriter(f, chunk_size=chunk_size, compression=comp,
                               flush_interval_ns=int(flush_interval * 1e9),
                               flush_interval_s=flush_interval, flush_messages=flush_messages)
    sess = _Session(w, res)
    backoff = 0.05
    ever_connected = False
    splitter = tw.FrameSplitter()
    sock: socket.socket | None = None
    try:
        while not stop.is_set():
            now = time.monotonic()
            if deadline is not None and now >= deadline:
                res.stopped_by = "duration"
                break
            if sock is None:
                try:
                    sock = socket.create_connection((host, port), timeout=1.0)
                    sock.settimeout(0.1)
                    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 21)
                    sock.sendall(auth)
                    splitter = tw.FrameSplitter()
                    sess.new_connection()
                    ever_connected = True
                    backoff = 0.05
                except OSError:
                    sock = None
                    if not ever_connected and deadline is None and \
                            now - t0 > connect_timeout:
                        raise ConnectionError(f"no telemetry at {host}:{port}") from None
                    if ever_connected and not reconnect:
                        res.stopped_by = "eof"
                        break
                    w.poll()
                    wait = backoff
                    if deadline is not None:
                        wait = min(wait, max(0.0, deadline - now))
                    stop.wait(wait)
                    backoff = min(backoff * 2, max_backoff)
                    continue
            try:
                data = sock.recv(1 << 18)
            except socket.timeout:
                w.poll()
                continue
            except OSError:
                data = b""
            if not data:
                sock.close()
                sock = None
                w.flush()  # the backoff may wait longer than the flush interval
                if not reconnect:
                    res.stopped_by = "eof"
                    break
                continue
            splitter.feed(data)
            try:
                sess.process(splitter.buf, splitter.frames())
            except tw.ProtocolError as e:
                hdr = bytes(splitter.buf[:tw.FRAME.size])
                typ, _fl, ln = tw.FRAME.unpack(hdr) if len(hdr) == tw.FRAME.size else (0, 0, 0)
                sess.bad_frame(typ, ln, f"{e}: framing lost, "
                               + ("reconnecting" if reconnect else "recording ends"))
                sock.close()
                sock = None
                w.flush()
                if not reconnect:
                    res.stopped_by = "protocol_error"
                    break
                continue
            if on_progress is not None:
                on_progress(res)
        else:
            res.stopped_by = "stop"
        if sock is None and ever_connected and reconnect and not sess.final_seen and \
                sess.last_cycle is not None and res.stopped_by != "eof":
            sess.gap(sess.last_t_ns, "reconnect", "recorder", sess.last_cycle + 1, None, None,
                     "connection lost; not re-established before the recording ended")
    finally:
        if sock is not None:
            sock.close()
        w.metadata("servoamp.recording", {
            "cycles": str(res.cycles), "connections": str(res.connections),
            "gaps": str(len(res.gaps)), "stopped_by": res.stopped_by or "error",
            "bad_frames": str(res.bad_frames),
            "bad_frames_by_type": json.dumps(res.bad_frames_by_type),
            "last_stats": json.dumps(res.last_stats)})
        w.finish()
        f.close()
        res.flushes = w.flushes
        res.messages = w.messages
        res.wall_s = time.monotonic() - t0
        res.cpu_s = time.process_time() - c0
    return res
