"""The servoamp telemetry wire format (docs/telemetry.md), version 1.

Decoding only: the producer is the C library in linux/telemetry/. A TCP
stream is a sequence of frames ``<u16 type, u16 flags, u32 length>`` followed
by ``length`` payload bytes, little-endian; the first frame is HELLO.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from typing import Iterator

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
    """The stream does not follow the wire format."""


def decode_hello(p: bytes | memoryview) -> Hello:
    if len(p) < HELLO.size:
        raise ProtocolError("short HELLO")
    magic, ver, _r, sid, t_ns, rt, n, period, hz, ring, cid = HELLO.unpack_from(p)
    if magic != MAGIC:
        raise ProtocolError(f"bad magic {magic:#x}")
    if ver != WIRE_VERSION:
        raise ProtocolError(f"wire version {ver}, this reader knows {WIRE_VERSION}")
    if not 1 <= n <= 64:
        raise ProtocolError(f"axis count {n}")
    return Hello(ver, sid, t_ns, rt, n, period, hz, ring, _cstr(cid))


def decode_stats(p: bytes | memoryview) -> Stats:
    f = STATS_HDR.unpack_from(p)
    n = f[14]
    counters = {}
    for k in range(min(n, (len(p) - STATS_HDR.size) // COUNTER.size)):
        name, val = COUNTER.unpack_from(p, STATS_HDR.size + k * COUNTER.size)
        counters[_cstr(name)] = val
    return Stats(f[0], f[1], f[2], f[3], f[4], f[5], f[6], f[7], f[8], f[9], f[10], f[11],
                 f[12], bool(f[13] & STATS_FINAL), counters)


def decode_param(p: bytes | memoryview) -> Param:
    t_ns, cyc, pid, typ, val, name, unit = PARAM.unpack_from(p)
    tname = PARAM_TYPES[typ] if typ < len(PARAM_TYPES) else str(typ)
    return Param(t_ns, cyc, pid, tname, val, _cstr(name), _cstr(unit))


def decode_log(p: bytes | memoryview) -> Log:
    t_ns, cyc, level, n, src = LOG_HDR.unpack_from(p)
    text = bytes(p[LOG_HDR.size:LOG_HDR.size + n]).decode("utf-8", "replace")
    return Log(t_ns, cyc, level, _cstr(src), text)


def decode_gap(p: bytes | memoryview) -> Gap:
    t_ns, frm, to, count, reason, _r = GAP.unpack_from(p)
    return Gap(t_ns, frm, to, count, GAP_REASONS.get(reason, f"reason_{reason}"))


def decode_queues(p: bytes | memoryview) -> Queues:
    t_ns, n, _r = QUEUES_HDR.unpack_from(p)
    levels = {}
    for k in range(min(n, (len(p) - QUEUES_HDR.size) // QUEUE.size)):
        name, level, cap = QUEUE.unpack_from(p, QUEUES_HDR.size + k * QUEUE.size)
        levels[_cstr(name)] = (level, cap)
    return Queues(t_ns, levels)


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
