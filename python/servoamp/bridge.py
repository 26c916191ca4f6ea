"""Live in Foxglove: the controller's telemetry over the Foxglove WebSocket
protocol and into MCAP, through the Foxglove SDK (foxglove-sdk).

    from servoamp.bridge import Bridge
    with Bridge("127.0.0.1", 7700, token=tok, mcap="run.mcap") as b:
        print(b.ws_url)                 # open it in Foxglove
        res = b.run(duration=10.0)

One set of channels, two sinks: a WebSocket server (default 127.0.0.1:8765)
and, with ``mcap``, an MCAP file; live and recorded data are the same
messages. Per-cycle data is protobuf (schemas/servoamp.proto, encoded by
:mod:`servoamp.pbenc`), the firmware trace foxglove.Log. The protocol's
parameters capability lists servod's parameters and sets them through the
telemetry connection (REQUEST frames, docs/telemetry.md "Requests"): servod
applies a set with the same handler as ``ampctl param set``, and the change
comes back as a PARAM event on /servoamp/param. A refused value comes back
to the app as an error status; nothing changes. docs/recording.md "Live".

Who may connect, and set parameters (:mod:`servoamp.wsfront`): the port is
served by a front that refuses foreign web origins before the upgrade and
gives the right to set parameters only to the URL with the bridge's token
(``ws_url``); the SDK's servers sit behind it on TLS. The recording is
flushed every ``flush_interval`` s of host time (SIGKILL loses at most that),
and a write error (a full disk) ends it cleanly: RecordingError, the file
readable up to the last flush.

CAN frames (``can_links``, bus -> canlink socket of our QEMU): every frame
on each emulated bus, on /servoamp/can<bus> (CanFrame), on the cycle
records' clock (:mod:`servoamp.bridge_can`); with ``telemetry=False`` the
bridge carries only those, on the emulator's virtual time (a machine
without servod). docs/recording.md "CAN frames".
"""

from __future__ import annotations

import json
import os
import secrets
import socket
import struct
import sys
import threading
import time
from pathlib import Path
from types import TracebackType
from typing import Any, Callable, Mapping

import foxglove
from foxglove import Channel, Schema
from foxglove.channels import LogChannel
from foxglove.mcap import MCAPCompression, MCAPWriteOptions
from foxglove.messages import Log, LogLevel, Timestamp
from foxglove.websocket import Capability

from servoamp import canlink, pbenc
from servoamp import telemetry as tw
from servoamp import wsfront
from servoamp.bridge_can import CAN_PENDING_MAX, T_CAN, TIME_STAMP_ID, CanTap  # noqa: F401
from servoamp.bridge_params import (MSG_REQUEST, READ_ONLY, REPLY_HDR, REQUEST_MAX,  # noqa: F401
                                    FrontAuth, Listener, ParamError, ParamInfo, ServodParams,
                                    fox_param, parse_param_list)
from servoamp.guestclock import GuestClock
from servoamp.record import RecordResult
from servoamp.schemas import servoamp_pb2 as pb

MSG_REPLY = 10    # server -> client: u32 id, i32 status, u32 n, text
# The recording is flushed (its chunk closed and written) at this much
# telemetry too: well under the SDK's chunk size (1 MiB), so that the SDK
# never writes a chunk by itself inside log(), where a write error (a full
# disk) only prints a line per message instead of raising.
FLUSH_BYTES = 1 << 18

T_CYCLE = "/servoamp/cycle"
T_PARAM = "/servoamp/param"
T_STATS = "/servoamp/stats"
T_LOG = "/servoamp/log"
T_GAP = "/servoamp/gap"
T_QUEUES = "/servoamp/queues"
T_SESSION = "/servoamp/session"

# topic -> protobuf message name (package servoamp); /servoamp/log is foxglove.Log
CHANNELS = {T_CYCLE: "Cycle", T_PARAM: "ParamChange", T_STATS: "Stats", T_GAP: "Gap",
            T_QUEUES: "QueueLevels", T_SESSION: "Session"}
TOPICS = sorted(list(CHANNELS) + [T_LOG])

_LEVELS = {0: LogLevel.Unknown, 1: LogLevel.Debug, 2: LogLevel.Info, 3: LogLevel.Warning,
           4: LogLevel.Error, 5: LogLevel.Fatal}


def is_loopback(host: str) -> bool:
    """127.0.0.0/8, ::1 or localhost."""
    import ipaddress

    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


class RecordingError(Exception):
    """The MCAP file could not be written (a full disk): recording stopped."""


class Bridge(ServodParams):
    """Telemetry client + Foxglove SDK sinks (WebSocket server, MCAP file)."""

    def __init__(self, host: str, port: int, *, token: bytes | str | None = None,
                 ws_host: str = "127.0.0.1", ws_port: int = 8765, serve: bool = True,
                 mcap: str | Path | None = None, reconnect: bool = True,
                 connect_timeout: float = 10.0, max_backoff: float = 2.0,
                 request_timeout: float = 10.0, message_backlog: int = 1 << 16,
                 params: bool = True, ws_token: str | None = None,
                 allow_origins: list[str] | tuple[str, ...] = wsfront.DEFAULT_ORIGINS,
                 flush_interval: float = 1.0, keep_live: bool = False,
                 can_links: Mapping[int, str | Path] | None = None, telemetry: bool = True,
                 on_progress: Callable[[RecordResult], None] | None = None) -> None:
        if not telemetry and not can_links:
            raise ValueError("without telemetry the bridge carries CAN frames only: give can_links")
        self.host, self.port = host, port
        self.telemetry = telemetry
        self.auth = tw.encode_auth(token)
        self.reconnect = reconnect
        self.connect_timeout = connect_timeout
        self.max_backoff = max_backoff
        self.on_progress = on_progress
        self.res = RecordResult(path=str(mcap) if mcap else "")
        self.ctx = foxglove.Context()
        self.fds = pbenc.file_descriptor_set()
        self.ch: dict[str, Channel] = {
            t: Channel(t, message_encoding="protobuf", context=self.ctx,
                       schema=Schema(name=f"servoamp.{m}", encoding="protobuf", data=self.fds))
            for t, m in CHANNELS.items()}
        self.ch_log = LogChannel(T_LOG, context=self.ctx)
        # telemetry state
        self.sock: socket.socket | None = None
        self._init_params(request_timeout)
        self.hello: tw.Hello | None = None
        # (cycle, t_ns) of the newest cycle record at the last STATS
        self.prev_stats: tuple[int, int] | None = None
        self.n_axes = 0
        self.enc: Callable[[bytes | bytearray, int], bytes] | None = None
        self.csize = 0
        self.expect: int | None = None
        self.last_cycle: int | None = None
        self.last_t_ns = 0
        self.pending_reconnect: tuple[int | None, bool] | None = None
        self.final_seen = False
        self.meta_written = False
        # the live view's subscriptions: (server, client id) -> topics
        self._subs: dict[tuple[bool, int], set[str]] = {}
        self._subs_lock = threading.Lock()
        self.params_on = params
        self.ws_token = ws_token or secrets.token_urlsafe(18)
        self.ws_host = ws_host
        self.flush_interval = flush_interval
        self.keep_live = keep_live
        self.record_error: str | None = None
        self._dirty = False
        self._pending_bytes = 0
        self._last_flush = time.monotonic()
        # the SDK's servers: read-write (the token's clients) and read-only,
        # on 127.0.0.1 behind TLS; the front on the bridge's port
        self.server = None
        self.server_ro = None
        self.front: wsfront.WsFront | None = None
        self.front_auth = FrontAuth()
        if serve:
            if not is_loopback(ws_host):
                raise ValueError(f"{ws_host} is not a loopback address: the live view is "
                                 "served on this machine only (use an SSH tunnel for "
                                 "another machine)")
            crt, key, tls = wsfront.new_tls()

            def sdk_server(name: str, writable: bool) -> Any:
                return foxglove.start_server(
                    name=name, host="127.0.0.1", port=0, context=self.ctx,
                    capabilities=[Capability.Parameters] if params else [],
                    server_listener=Listener(self, writable),
                    message_backlog_size=message_backlog, tls_cert=crt, tls_key=key)

            try:
                self.server = sdk_server("servoamp", writable=True)
                self.server_ro = sdk_server("servoamp (read-only)", writable=False)
                # a taken port raises here, before any file is opened
                self.front = wsfront.WsFront(ws_host, ws_port, upstream_rw=self.server.port,
                                             upstream_ro=self.server_ro.port, tls=tls,
                                             token=self.ws_token, origins=allow_origins,
                                             vouch=self.front_auth.issue)
            except BaseException:
                self._stop_servers()
                raise
        self.mcap = None
        self.mcap_path = str(mcap) if mcap is not None else None
        if mcap is not None:
            self.mcap = foxglove.open_mcap(
                str(mcap), allow_overwrite=True, context=self.ctx,
                writer_options=MCAPWriteOptions(compression=MCAPCompression.Zstd,
                                                chunk_size=1 << 20))
        # CAN: a passive canlink client and a reader thread per bus; without
        # telemetry (no cycle records) on the emulator's virtual time
        self.clock = GuestClock() if telemetry else GuestClock.virtual()
        self.can: CanTap | None = None
        self.can_errors: dict[int, str] = {}
        if can_links:
            try:
                self.can = CanTap(self.ctx, self.fds, self.res, self.clock, can_links,
                                  connect_timeout, self._mark_dirty)
            except BaseException:
                self.close()
                raise
            self.can_errors = self.can.errors

    def _mark_dirty(self) -> None:
        self._dirty = True

    # -- the app's side ----------------------------------------------------------------
    @property
    def ws_port(self) -> int | None:
        return self.front.port if self.front is not None else None

    @property
    def ws_url(self) -> str | None:
        """The URL to open in Foxglove: with the token, which gives the right
        to set parameters (without it: read-only, from allowed origins)."""
        if self.front is None:
            return None
        return f"{self.ws_url_plain}?token={self.ws_token}"

    @property
    def ws_url_plain(self) -> str | None:
        """The URL without the token: a read-only view."""
        if self.front is None:
            return None
        h = self.ws_host if ":" not in self.ws_host else f"[{self.ws_host.strip('[]')}]"
        return f"ws://{h}:{self.front.port}/"

    @property
    def servers(self) -> list[Any]:
        return [s for s in (self.server, self.server_ro) if s is not None]

    def _stop_servers(self) -> None:
        if self.front is not None:
            self.front.close()
            self.front = None
        for s in self.servers:
            s.stop()
        self.server = self.server_ro = None

    def __enter__(self) -> Bridge:
        return self

    def __exit__(self, et: type[BaseException] | None, ev: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def close(self) -> None:
        """Ends the bridge; a write error while closing the recording sets
        record_error (never raises)."""
        if self.sock is not None:
            self.sock.close()
            self.sock = None
        if self.can is not None:
            self.can.close()
        self._stop_servers()
        if self.mcap is not None:
            m, self.mcap = self.mcap, None
            meta = {"cycles": str(self.res.cycles), "connections": str(self.res.connections),
                    "gaps": str(len(self.res.gaps)), "stopped_by": self.res.stopped_by or "error",
                    "last_stats": json.dumps(self.res.last_stats)}
            if self.can is not None:
                meta |= self.can.metadata()
            try:
                m.write_metadata("servoamp.recording", meta)
                m.close()
            except (RuntimeError, OSError) as e:
                self.record_error = self._record_error_text(e)
                try:
                    m.close()
                except (RuntimeError, OSError):
                    pass

    # -- the recording's bound on loss --------------------------------------------------
    def _record_error_text(self, e: BaseException) -> str:
        where = self.mcap_path or "?"
        try:
            st = os.statvfs(os.path.dirname(os.path.abspath(where)) or ".")
            free = f"{st.f_bavail * st.f_frsize} bytes free on its filesystem"
        except OSError:
            free = "its filesystem unreadable"
        last = f"up to cycle {self.last_cycle}" if self.last_cycle is not None else "before"
        return (f"recording to {where} stopped: {e} ({free}); the file holds what was "
                f"written {last}, readable without its summary")

    def flush_recording(self, force: bool = False) -> None:
        """Hands the open chunk to the OS when messages have waited for
        flush_interval s (or force). A write error: RecordingError, or with
        keep_live one message on stderr and the live view goes on."""
        if self.mcap is None or not self._dirty:
            return
        now = time.monotonic()
        if not force and now - self._last_flush < self.flush_interval and \
                self._pending_bytes < FLUSH_BYTES:
            return
        self._last_flush = now
        self._dirty = False
        self._pending_bytes = 0
        try:
            self.mcap.flush()
        except (RuntimeError, OSError) as e:
            msg = self._record_error_text(e)
            self.record_error = msg
            m, self.mcap = self.mcap, None
            try:
                m.close()
            except (RuntimeError, OSError):
                pass
            if not self.keep_live:
                raise RecordingError(msg) from None
            print(f"servoamp bridge: {msg}; the live view goes on", file=sys.stderr, flush=True)

    def subscribed(self, topics: set[str] | frozenset[str]) -> bool:
        """True when one live-view client (on either server) has subscribed
        to every one of topics: from then on it gets each message logged on
        them (a client that connected is not subscribed yet)."""
        with self._subs_lock:
            return any(topics <= t for t in self._subs.values())

    def _subscription(self, writable: bool, client: int, topic: str, on: bool) -> None:
        with self._subs_lock:
            t = self._subs.setdefault((writable, client), set())
            if on:
                t.add(topic)
            else:
                t.discard(topic)

    # -- telemetry -> channels ----------------------------------------------------------
    def _gap(self, t_ns: int, reason: str, source: str, frm: int | None, to: int | None,
             lost: int | None, detail: str) -> None:
        g = pb.Gap(reason=reason, source=source, detail=detail)
        if frm is not None:
            g.from_cycle = frm
        if to is not None:
            g.to_cycle = to
        if lost is not None:
            g.lost = lost
        self.ch[T_GAP].log(g.SerializeToString(), log_time=t_ns)
        self._dirty = True
        self.res.gaps.append({"reason": reason, "source": source, "from_cycle": frm,
                              "to_cycle": to, "lost": lost, "detail": detail, "t_ns": t_ns})

    def _on_hello(self, h: tw.Hello) -> None:
        prev = self.hello
        self.res.connections += 1
        if prev is not None:
            self.pending_reconnect = (self.last_cycle, prev.session_id != h.session_id)
            self.expect = None
        self.hello = h
        self.prev_stats = None  # the rate starts again on every connection
        self.res.controller_id = h.controller_id
        self.final_seen = False
        tick_ns = 1e9 / h.clock_hz if h.clock_hz else 0.0
        self.n_axes = h.n_axes
        self.enc = pbenc.cycle_encoder(h.n_axes, tick_ns)
        self.csize = tw.cycle_struct(h.n_axes).size
        self.ch[T_SESSION].log(pb.Session(
            connection=self.res.connections, controller_id=h.controller_id,
            session_id=f"{h.session_id:016x}", wire_version=h.version, n_axes=h.n_axes,
            cycle_period_ns=h.cycle_period_ns, clock_hz=h.clock_hz,
            ring_capacity=h.ring_capacity, realtime_ns=h.realtime_ns).SerializeToString(),
            log_time=h.t_ns)
        if not self.meta_written and self.mcap is not None:
            self.meta_written = True
            self.mcap.write_metadata("servoamp", {**tw.hello_metadata(h), "encoding": "protobuf"})

    def _cycle_discontinuity(self, cyc: int, t_ns: int) -> None:
        g = tw.receiver_gap(self.pending_reconnect, self.expect, cyc)
        self.pending_reconnect = None
        if g is not None:
            self._gap(t_ns, g[0], "recorder", *g[1:])

    def _process(self, buf: bytearray, frames: Any) -> None:
        log_cycle = self.ch[T_CYCLE].log
        enc = self.enc
        csize = self.csize
        cyc_from = struct.Struct("<QQ").unpack_from
        cycles = 0
        nmsg = 0
        t_ns = self.last_t_ns
        for typ, off, ln in frames:
            if typ == tw.MSG_CYCLE:
                if enc is None or ln < csize:
                    raise tw.ProtocolError(f"CYCLE of {ln} bytes, expected {csize}")
                cyc, t_ns = cyc_from(buf, off)
                if self.can is not None and self.can.wants_cycles:
                    self.can.cycle_sample(buf, off, self.hello.clock_hz if self.hello else 0)
                if cyc != self.expect:
                    self._cycle_discontinuity(cyc, t_ns)
                self.expect = cyc + 1
                log_cycle(enc(buf, off), log_time=t_ns)
                cycles += 1
                nmsg += 1
                if self.res.first_cycle is None:
                    self.res.first_cycle = cyc
                self.last_cycle = cyc
                continue
            p = bytes(buf[off:off + ln])
            nmsg += 1
            if typ == tw.MSG_HELLO:
                self._on_hello(tw.decode_hello(p))
                enc = self.enc
                csize = self.csize
            elif typ == tw.MSG_STATS:
                s = tw.decode_stats(p)
                # the rate over the cycle records' own times (cycle counter
                # and t_ns of the newest record at this STATS and the last)
                rate = None
                now = (self.last_cycle, t_ns) if self.last_cycle is not None else None
                prev = self.prev_stats
                if prev is not None and now is not None:
                    if now[0] == prev[0]:
                        rate = 0.0  # no cycle since: stopped, or recovering
                    elif now[0] > prev[0] and now[1] > prev[1]:
                        rate = (now[0] - prev[0]) * 1e9 / (now[1] - prev[1])
                self.prev_stats = now
                d = {"last_cycle": s.last_cycle, "pushed": s.pushed, "dropped": s.dropped,
                     "drained": s.drained, "client_lost": s.client_lost,
                     "client_events_lost": s.client_events_lost, "events": s.events,
                     "events_dropped": s.events_dropped, "bytes_sent": s.bytes_sent,
                     "ring_high_water": s.ring_high_water, "ring_capacity": s.ring_capacity,
                     "clients": s.clients, "final": s.final}
                self.ch[T_STATS].log(pb.Stats(
                    last_cycle=s.last_cycle, pushed=s.pushed, dropped=s.dropped,
                    drained=s.drained, client_lost=s.client_lost,
                    client_events_lost=s.client_events_lost, events=s.events,
                    events_dropped=s.events_dropped, bytes_sent=s.bytes_sent,
                    ring_high_water=s.ring_high_water, ring_capacity=s.ring_capacity,
                    clients=s.clients, final=s.final, counters=s.counters,
                    cycle_rate_hz=rate).SerializeToString(),
                    log_time=s.t_ns)
                self.res.last_stats = dict(d, counters=s.counters)
                self.final_seen = self.final_seen or s.final
            elif typ == tw.MSG_PARAM:
                q = tw.decode_param(p)
                self.ch[T_PARAM].log(pb.ParamChange(
                    cycle=q.cycle, id=q.id, name=q.name, type=q.type, value=q.value,
                    unit=q.unit).SerializeToString(), log_time=q.t_ns)
                info = self.params.get(q.name)
                if info is not None:
                    info.value = q.value if info.type == "f32" else int(q.value)
                if self.params_on:
                    for srv in self.servers:
                        srv.publish_parameter_values([fox_param(q.name, q.type, q.value)])
            elif typ == tw.MSG_LOG:
                lg = tw.decode_log(p)
                self.ch_log.log(Log(timestamp=Timestamp(lg.t_ns // 1_000_000_000,
                                                        lg.t_ns % 1_000_000_000),
                                    level=_LEVELS.get(lg.level, LogLevel.Unknown),
                                    message=lg.text, name=lg.source), log_time=lg.t_ns)
            elif typ == tw.MSG_GAP:
                g = tw.decode_gap(p)
                self._gap(g.t_ns, g.reason, "controller", g.from_cycle, g.to_cycle, g.count,
                          f"announced by the controller ({g.count} records)")
                if g.count and g.reason in ("ring_overflow", "client_overflow"):
                    self.expect = g.to_cycle + 1
            elif typ == tw.MSG_QUEUES:
                qu = tw.decode_queues(p)
                self.ch[T_QUEUES].log(pb.QueueLevels(
                    levels={k: lv for k, (lv, _c) in qu.levels.items()},
                    capacity={k: c for k, (_lv, c) in qu.levels.items()}).SerializeToString(),
                    log_time=qu.t_ns)
            elif typ == MSG_REPLY:
                nmsg -= 1
                self._on_reply(p)
            else:
                nmsg -= 1  # unknown types are skipped (forward compatible)
        self.last_t_ns = t_ns
        self.res.cycles += cycles
        self.res.messages += nmsg
        if nmsg:
            self._dirty = True
        if self.last_cycle is not None:
            self.res.last_cycle = self.last_cycle

    def run(self, duration: float | None = None, stop: threading.Event | None = None
            ) -> RecordResult:
        """Stream until duration (s, wall clock) elapses, stop is set, or
        (reconnect=False) the stream ends. Reconnects like ``servoamp record``.
        Without telemetry: until duration, stop, or every CAN bus ended
        (QEMU's BYE)."""
        stop = stop or threading.Event()
        res = self.res
        t0 = time.monotonic()
        c0 = time.process_time()
        deadline = t0 + duration if duration is not None else None
        backoff = 0.05
        ever = False
        splitter = tw.FrameSplitter()
        try:
            while not stop.is_set():
                self.flush_recording()
                now = time.monotonic()
                if deadline is not None and now >= deadline:
                    res.stopped_by = "duration"
                    break
                if not self.telemetry:
                    # CAN frames only: their readers log; the recording is
                    # flushed here; the end when every bus is gone (QEMU quit)
                    if self.can is not None and self.can.ended:
                        res.stopped_by = "eof"
                        break
                    stop.wait(self.flush_interval if deadline is None
                              else min(self.flush_interval, max(0.0, deadline - now)))
                    continue
                if self.sock is None:
                    try:
                        s = socket.create_connection((self.host, self.port), timeout=1.0)
                        s.settimeout(0.1)
                        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 21)
                        s.sendall(self.auth)
                        with self.send_lock:
                            self.sock = s
                        splitter = tw.FrameSplitter()
                        ever = True
                        backoff = 0.05
                    except OSError:
                        if not ever and deadline is None and now - t0 > self.connect_timeout:
                            raise ConnectionError(
                                f"no telemetry at {self.host}:{self.port}") from None
                        if ever and not self.reconnect:
                            res.stopped_by = "eof"
                            break
                        wait = backoff if deadline is None else min(backoff,
                                                                   max(0.0, deadline - now))
                        stop.wait(min(wait, self.flush_interval))
                        backoff = min(backoff * 2, self.max_backoff)
                        continue
                try:
                    data = self.sock.recv(1 << 18)
                except socket.timeout:
                    continue
                except OSError:
                    data = b""
                if not data:
                    with self.send_lock:
                        self.sock.close()
                        self.sock = None
                    self._fail_pending("connection to the controller lost")
                    if not self.reconnect:
                        res.stopped_by = "eof"
                        break
                    continue
                splitter.feed(data)
                self._pending_bytes += len(data)
                self._process(splitter.buf, splitter.frames())
                if self.on_progress is not None:
                    self.on_progress(res)
            else:
                res.stopped_by = "stop"
            if self.sock is None and ever and self.reconnect and not self.final_seen and \
                    self.last_cycle is not None and res.stopped_by != "eof":
                self._gap(self.last_t_ns, "reconnect", "recorder", self.last_cycle + 1, None,
                          None, "connection lost; not re-established before the end")
        finally:
            res.wall_s = time.monotonic() - t0
            res.cpu_s = time.process_time() - c0
        return res
