"""The servoamp telemetry wire format (docs/telemetry.md), version 1.

Decoding only: the producer is the C library in linux/telemetry/. A TCP
stream is a sequence of frames ``<u16 type, u16 flags, u32 length>`` followed
by ``length`` payload bytes, little-endian; the first frame is HELLO.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field
from typing import Callable, Iterator

WIRE_VERSION = 1
MAGIC = 0x4D4C5453  # "STLM"

MSG_HELLO = 1
MSG_CYCLE = 2
MSG_STATS = 3
MSG_PARAM = 4
MSG_LOG = 5
MSG_GAP = 6
MSG_QUEUES = 7
MSG_AUTH = 8  # client -> server: the first and only frame a client sends
TOKEN_MAX = 64

FRAME = struct.Struct("<HHI")
HELLO = struct.Struct("<IHHQQQIIII32s")
CYCLE_HDR = struct.Struct("<QQIIIIIIIiI")
AXIS_FMT = "IiiiIiiii"  # command (4 words) then feedback (5 words)
AXIS_WORDS = 9
STATS_HDR = struct.Struct("<QQQQQQQQQQIIIIII")
COUNTER = struct.Struct("<24sQ")
PARAM = struct.Struct("<QQIId32s16s")
LOG_HDR = struct.Struct("<QQII16s")
GAP = struct.Struct("<QQQQII")
QUEUES_HDR = struct.Struct("<QII")
QUEUE = struct.Struct("<16sII")

assert FRAME.size == 8 and HELLO.size == 80 and CYCLE_HDR.size == 52
assert STATS_HDR.size == 104 and COUNTER.size == 32 and PARAM.size == 80
assert LOG_HDR.size == 40 and GAP.size == 40 and QUEUES_HDR.size == 16 and QUEUE.size == 24


def encode_auth(token: bytes | str | None = None) -> bytes:
    """The AUTH frame a client sends right after connecting (docs/telemetry.md):
    the shared token as payload, empty when the server has none."""
    t = token.encode() if isinstance(token, str) else (token or b"")
    if len(t) > TOKEN_MAX:
        raise ValueError(f"telemetry token longer than {TOKEN_MAX} bytes")
    return FRAME.pack(MSG_AUTH, 0, len(t)) + t


def read_token(path: str) -> bytes:
    """A token file as servod reads it: its bytes without trailing whitespace."""
    with open(path, "rb") as f:
        return f.read().rstrip()

EXCHANGE_NAMES = ("fresh", "stale", "torn", "missed", "invalid", "none")
GAP_REASONS = {1: "ring_overflow", 2: "client_overflow", 3: "controller_restart",
               4: "recovery", 5: "other"}
PARAM_TYPES = ("u32", "i32", "f32", "f64")
STATS_FINAL = 1


def _cstr(b: bytes) -> str:
    return b.split(b"\0", 1)[0].decode("utf-8", "replace")


def exchange_name(code: int) -> str:
    return EXCHANGE_NAMES[code] if 0 <= code < len(EXCHANGE_NAMES) else f"unknown_{code}"


def cycle_struct(n_axes: int) -> struct.Struct:
    """The whole CYCLE payload for n_axes axes: 11 header fields, then 9 per axis."""
    return struct.Struct("<QQIIIIIIIiI" + AXIS_FMT * n_axes)


@dataclass(frozen=True)
class Hello:
    version: int
    session_id: int
    t_ns: int
    realtime_ns: int
    n_axes: int
    cycle_period_ns: int
    clock_hz: int
    ring_capacity: int
    controller_id: str


def hello_metadata(h: Hello) -> dict[str, str]:
    """The recording's "servoamp" metadata record, from the first HELLO
    (servoamp record and servoamp bridge write the same keys)."""
    return {
        "controller_id": h.controller_id, "n_axes": str(h.n_axes),
        "cycle_period_ns": str(h.cycle_period_ns), "clock_hz": str(h.clock_hz),
        "wire_version": str(h.version), "session_id": f"{h.session_id:016x}",
        "realtime_minus_monotonic_ns": str(h.realtime_ns - h.t_ns),
        "time_base": "controller CLOCK_MONOTONIC (ns)",
    }


@dataclass(frozen=True)
class Stats:
    t_ns: int
    last_cycle: int
    pushed: int
    dropped: int
    drained: int
    client_lost: int
    client_events_lost: int
    events: int
    events_dropped: int
    bytes_sent: int
    ring_high_water: int
    ring_capacity: int
    clients: int
    final: bool
    counters: dict[str, int] = field(default_factory=dict)


@dataclass(frozen=True)
class Param:
    t_ns: int
    cycle: int
    id: int
    type: str
    value: float
    name: str
    unit: str


@dataclass(frozen=True)
class Log:
    t_ns: int
    cycle: int
    level: int
    source: str
    text: str


@dataclass(frozen=True)
class Gap:
    t_ns: int
    from_cycle: int
    to_cycle: int
    count: int
    reason: str


@dataclass(frozen=True)
class Queues:
    t_ns: int
    levels: dict[str, tuple[int, int]]  # name -> (level, capacity)


class ProtocolError(Exception):
    """The stream does not follow the wire format.

    The one exception the decoders below and FrameSplitter raise for bad
    input, whatever the bytes (tests/fuzz/test_telemetry_decoder.py checks
    it): a payload shorter than its type needs, a count or length field that
    points past the payload, or a value outside the field's range.
    """


LOG_TEXT_MAX = 480
QUEUES_MAX = 8
COUNTERS_MAX = 64


def _need(p: bytes | memoryview, n: int, what: str) -> None:
    if len(p) < n:
        raise ProtocolError(f"{what} of {len(p)} bytes, expected at least {n}")


def decode_hello(p: bytes | memoryview) -> Hello:
    _need(p, HELLO.size, "HELLO")
    magic, ver, _r, sid, t_ns, rt, n, period, hz, ring, cid = HELLO.unpack_from(p)
    if magic != MAGIC:
        raise ProtocolError(f"bad magic {magic:#x}")
    if ver != WIRE_VERSION:
        raise ProtocolError(f"wire version {ver}, this reader knows {WIRE_VERSION}")
    if not 1 <= n <= 64:
        raise ProtocolError(f"axis count {n}")
    return Hello(ver, sid, t_ns, rt, n, period, hz, ring, _cstr(cid))


def decode_cycle(p: bytes | memoryview, n_axes: int) -> tuple[int | float, ...]:
    """The CYCLE payload as the flat tuple of cycle_struct(n_axes) (the
    recorder unpacks it inline with the same length check)."""
    if not 0 <= n_axes <= 64:
        raise ProtocolError(f"axis count {n_axes}")
    st = cycle_struct(n_axes)
    _need(p, st.size, f"CYCLE ({n_axes} axes)")
    return st.unpack_from(p)


def decode_stats(p: bytes | memoryview) -> Stats:
    _need(p, STATS_HDR.size, "STATS")
    f = STATS_HDR.unpack_from(p)
    n = f[14]
    if n > COUNTERS_MAX or len(p) < STATS_HDR.size + n * COUNTER.size:
        raise ProtocolError(f"STATS with {n} counters in {len(p)} bytes")
    counters = {}
    for k in range(n):
        name, val = COUNTER.unpack_from(p, STATS_HDR.size + k * COUNTER.size)
        counters[_cstr(name)] = val
    return Stats(f[0], f[1], f[2], f[3], f[4], f[5], f[6], f[7], f[8], f[9], f[10], f[11],
                 f[12], bool(f[13] & STATS_FINAL), counters)


def decode_param(p: bytes | memoryview) -> Param:
    _need(p, PARAM.size, "PARAM")
    t_ns, cyc, pid, typ, val, name, unit = PARAM.unpack_from(p)
    if typ >= len(PARAM_TYPES):
        raise ProtocolError(f"PARAM type {typ}")
    if not math.isfinite(val):
        raise ProtocolError(f"PARAM value {val} is not a finite number")
    return Param(t_ns, cyc, pid, PARAM_TYPES[typ], val, _cstr(name), _cstr(unit))


def decode_log(p: bytes | memoryview) -> Log:
    _need(p, LOG_HDR.size, "LOG")
    t_ns, cyc, level, n, src = LOG_HDR.unpack_from(p)
    if n > LOG_TEXT_MAX or len(p) < LOG_HDR.size + n:
        raise ProtocolError(f"LOG with {n} text bytes in {len(p)} bytes")
    text = bytes(p[LOG_HDR.size:LOG_HDR.size + n]).decode("utf-8", "replace")
    return Log(t_ns, cyc, level, _cstr(src), text)


def decode_gap(p: bytes | memoryview) -> Gap:
    _need(p, GAP.size, "GAP")
    t_ns, frm, to, count, reason, _r = GAP.unpack_from(p)
    if reason not in GAP_REASONS:
        raise ProtocolError(f"GAP reason {reason}")
    return Gap(t_ns, frm, to, count, GAP_REASONS[reason])


def decode_queues(p: bytes | memoryview) -> Queues:
    _need(p, QUEUES_HDR.size, "QUEUES")
    t_ns, n, _r = QUEUES_HDR.unpack_from(p)
    if n > QUEUES_MAX or len(p) < QUEUES_HDR.size + n * QUEUE.size:
        raise ProtocolError(f"QUEUES with {n} queues in {len(p)} bytes")
    levels = {}
    for k in range(n):
        name, level, cap = QUEUE.unpack_from(p, QUEUES_HDR.size + k * QUEUE.size)
        levels[_cstr(name)] = (level, cap)
    return Queues(t_ns, levels)


MSG_NAMES = {MSG_HELLO: "HELLO", MSG_CYCLE: "CYCLE", MSG_STATS: "STATS", MSG_PARAM: "PARAM",
             MSG_LOG: "LOG", MSG_GAP: "GAP", MSG_QUEUES: "QUEUES", MSG_AUTH: "AUTH"}

Decoded = Hello | Stats | Param | Log | Gap | Queues | tuple[int | float, ...] | None


def msg_name(typ: int) -> str:
    return MSG_NAMES.get(typ, f"type_{typ}")


def decode(typ: int, p: bytes | memoryview, n_axes: int = 0) -> Decoded:
    """Any server-to-client frame's payload: the decoded message, or None for a
    type this reader does not know (skipped: forward compatible). CYCLE needs
    the axis count of the connection's HELLO. Raises only ProtocolError."""
    if typ == MSG_CYCLE:
        return decode_cycle(p, n_axes)
    dec = _DECODERS.get(typ)
    return dec(p) if dec is not None else None


_DECODERS: dict[int, Callable[[bytes | memoryview], Decoded]] = {
    MSG_HELLO: decode_hello, MSG_STATS: decode_stats, MSG_PARAM: decode_param,
    MSG_LOG: decode_log, MSG_GAP: decode_gap, MSG_QUEUES: decode_queues,
}


class FrameSplitter:
    """Cuts a byte stream into (type, payload offset, payload length) frames.

    feed() appends received bytes; frames() yields complete frames found in
    the internal buffer (payload bytes at buf[off:off+length]) and, when the
    iteration ends, drops the consumed bytes.
    """

    MAX_FRAME = 1 << 20

    def __init__(self) -> None:
        self.buf = bytearray()

    def feed(self, data: bytes | bytearray | memoryview) -> None:
        self.buf += data

    def frames(self) -> Iterator[tuple[int, int, int]]:
        buf = self.buf
        off = 0
        end = len(buf)
        unpack = FRAME.unpack_from
        try:
            while end - off >= 8:
                typ, _flags, length = unpack(buf, off)
                if length > self.MAX_FRAME:
                    raise ProtocolError(f"frame of {length} bytes")
                if end - off - 8 < length:
                    break
                yield typ, off + 8, length
                off += 8 + length
        finally:
            if off:
                del buf[:off]


# ---- encoding: the server's side, for stand-in servers, tests and fuzzing ----------
# (the producer is linux/telemetry/: telem_wire.c, telem_push.c, and telem_drain.c for STATS;
# these follow docs/telemetry.md)

def encode_frame(typ: int, payload: bytes, flags: int = 0) -> bytes:
    return FRAME.pack(typ, flags, len(payload)) + payload


def encode_hello(n_axes: int, session_id: int = 1, t_ns: int = 0, realtime_ns: int = 0,
                 cycle_period_ns: int = 1_000_000, clock_hz: int = 100_000_000,
                 ring_capacity: int = 4096, controller_id: str = "test") -> bytes:
    return encode_frame(MSG_HELLO, HELLO.pack(MAGIC, WIRE_VERSION, 0, session_id, t_ns,
                                              realtime_ns, n_axes, cycle_period_ns, clock_hz,
                                              ring_capacity, controller_id.encode()))


def encode_cycle(n_axes: int, cycle: int, t_ns: int, exchange: int = 0,
                 axes: list[tuple[int, ...]] | None = None) -> bytes:
    """axes: per axis the 9 words (command 4, feedback 5); default zeros."""
    words: list[int] = []
    for i in range(n_axes):
        words += list(axes[i]) if axes is not None else [0] * AXIS_WORDS
    return encode_frame(MSG_CYCLE, cycle_struct(n_axes).pack(
        cycle, t_ns, cycle & 0xFFFFFFFF, 0, 0, 0, exchange, 0, 0, 0, n_axes, *words))


def encode_stats(t_ns: int, last_cycle: int = 0, final: bool = False,
                 counters: dict[str, int] | None = None) -> bytes:
    c = counters or {}
    p = STATS_HDR.pack(t_ns, last_cycle, last_cycle, 0, last_cycle, 0, 0, 0, 0, 0, 0, 4096, 1,
                       STATS_FINAL if final else 0, len(c), 0)
    p += b"".join(COUNTER.pack(k.encode(), v) for k, v in c.items())
    return encode_frame(MSG_STATS, p)


def encode_param(t_ns: int, cycle: int, pid: int, value: float, name: str, unit: str = "",
                 typ: int = 3) -> bytes:
    return encode_frame(MSG_PARAM, PARAM.pack(t_ns, cycle, pid, typ, value, name.encode(),
                                              unit.encode()))


def encode_log(t_ns: int, cycle: int, text: str, level: int = 2, source: str = "test") -> bytes:
    b = text.encode()
    return encode_frame(MSG_LOG, LOG_HDR.pack(t_ns, cycle, level, len(b), source.encode()) + b)


def encode_gap(t_ns: int, frm: int, to: int, count: int, reason: int) -> bytes:
    return encode_frame(MSG_GAP, GAP.pack(t_ns, frm, to, count, reason, 0))


def encode_queues(t_ns: int, levels: dict[str, tuple[int, int]]) -> bytes:
    p = QUEUES_HDR.pack(t_ns, len(levels), 0)
    p += b"".join(QUEUE.pack(k.encode(), lv, cap) for k, (lv, cap) in levels.items())
    return encode_frame(MSG_QUEUES, p)


# ---- continuity, as a recorder sees it -------------------------------------------------

def receiver_gap(reconnect: tuple[int | None, bool] | None, expect: int | None,
                 cyc: int) -> tuple[str, int, int | None, int | None, str] | None:
    """The gap a receiver (recorder, bridge) declares before cycle ``cyc``:
    after a reconnect (``reconnect`` = (last cycle received or None, whether
    the producer's session changed)), or when ``cyc`` is not the ``expect``-ed
    next cycle. Returns (reason, from_cycle, to_cycle, lost, detail), with
    None for what is not known, or None when there is no gap."""
    if reconnect is not None:
        last, new_session = reconnect
        if last is None:
            return None
        if new_session:
            return ("producer_restart", last + 1, cyc - 1 if cyc > last else None, None,
                    "telemetry producer restarted (new session); cycles in between were not received")
        return ("reconnect", last + 1, cyc - 1, cyc - last - 1 if cyc > last else None,
                "connection lost and re-established")
    if expect is not None and cyc != expect:
        return ("other", expect, cyc - 1, cyc - expect if cyc > expect else None,
                "cycle counter discontinuity not announced by the controller")
    return None
