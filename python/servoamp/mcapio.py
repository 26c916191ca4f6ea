"""MCAP files of servoamp recordings: channels, JSON schemas, writer, reader.

``servoamp record`` writes JSON messages (message encoding ``json``)
described by a JSON Schema (schema encoding ``jsonschema``), which Foxglove
opens as they are; ``servoamp bridge`` writes protobuf (schemas/servoamp.proto,
through the Foxglove SDK). :func:`iter_json` reads both into the same dicts. log_time and publish_time are the controller's own clock
(CLOCK_MONOTONIC of the Linux side, ns). docs/recording.md lists the topics.
"""

from __future__ import annotations

import json
import struct
import time
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any, Iterable, Iterator

from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, IndexType, Writer

PROFILE = ""  # JSON messages: no ROS profile
LIBRARY = "servoamp"

T_CYCLE = "/servoamp/cycle"
T_PATH = "/servoamp/path"
T_STATS = "/servoamp/stats"
T_PARAM = "/servoamp/param"
T_LOG = "/servoamp/log"
T_GAP = "/servoamp/gap"
T_QUEUES = "/servoamp/queues"
T_SESSION = "/servoamp/session"


def axis_topic(i: int) -> str:
    return f"/servoamp/axis/{i}"


_INT = {"type": "integer"}
_U32 = {"type": "integer", "minimum": 0, "maximum": 0xFFFFFFFF}
_I32 = {"type": "integer", "minimum": -(2**31), "maximum": 2**31 - 1}
_U64 = {"type": "integer", "minimum": 0}


def _obj(props: dict[str, Any], title: str, desc: str = "") -> dict[str, Any]:
    s: dict[str, Any] = {"type": "object", "properties": props, "required": list(props),
                         "additionalProperties": False}
    if title:
        s["title"] = title
    if desc:
        s["description"] = desc
    return s


SCHEMAS: dict[str, dict[str, Any]] = {
    "servoamp.AxisSample": _obj({
        "cycle": _U64,
        "axis": {"type": "integer", "minimum": 0},
        "command": _obj({
            "control_word": _U32, "target_pos": _I32, "vel_ff": _I32, "torque_offset": _I32,
        }, "", "amp_cmd_axis: position in increments, velocity in increments/s, "
               "torque offset in milli-percent"),
        "feedback": _obj({
            "status_word": _U32, "actual_pos": _I32, "actual_vel": _I32, "current": _I32,
            "following_error": _I32,
        }, "", "amp_fb_axis: increments, increments/s, mA"),
    }, "servoamp.AxisSample", "One axis in one cycle: command sent and feedback read"),
    "servoamp.Cycle": _obj({
        "cycle": _U64,
        "servo_cycle": _U32,
        "t_cycle": _U32,
        "irq_latency_ticks": _U32,
        "irq_latency_ns": {"type": "number", "minimum": 0},
        "wake_latency_ns": _U32,
        "exchange": {"enum": ["fresh", "stale", "torn", "missed", "invalid", "none"]},
        "exchange_code": {"type": "integer", "minimum": 0},
        "missed": _U32,
        "servo_status": _U32,
        "result": _I32,
    }, "servoamp.Cycle", "Cycle timing, latencies and exchange status"),
    "servoamp.Path": _obj({
        "cycle": _U64,
        "command": _obj({"x": _I32, "y": _I32}, ""),
        "actual": _obj({"x": _I32, "y": _I32}, ""),
    }, "servoamp.Path", "XY path of axes 0 (x) and 1 (y): commanded and actual"),
    "servoamp.Stats": _obj({
        "last_cycle": _U64, "pushed": _U64, "dropped": _U64, "drained": _U64,
        "client_lost": _U64, "client_events_lost": _U64, "events": _U64,
        "events_dropped": _U64, "bytes_sent": _U64, "ring_high_water": _U32,
        "ring_capacity": _U32, "clients": _U32, "final": {"type": "boolean"},
        "counters": {"type": "object", "additionalProperties": _U64},
    }, "servoamp.Stats", "Telemetry transport and controller counters"),
    "servoamp.ParamChange": _obj({
        "cycle": _U64, "id": _U32, "name": {"type": "string"},
        "type": {"enum": ["u32", "i32", "f32", "f64"]}, "value": {"type": "number"},
        "unit": {"type": "string"},
    }, "servoamp.ParamChange", "A servo parameter was set"),
    "servoamp.Gap": _obj({
        "reason": {"enum": ["ring_overflow", "client_overflow", "controller_restart",
                            "recovery", "other", "reconnect", "producer_restart"]},
        "source": {"enum": ["controller", "recorder"]},
        "from_cycle": {"type": ["integer", "null"]},
        "to_cycle": {"type": ["integer", "null"]},
        "lost": {"type": ["integer", "null"], "minimum": 0},
        "detail": {"type": "string"},
    }, "servoamp.Gap", "Cycles missing from the record, and why (to_cycle inclusive)"),
    "servoamp.QueueLevels": _obj({
        "levels": {"type": "object", "additionalProperties": _U32},
        "capacity": {"type": "object", "additionalProperties": _U32},
    }, "servoamp.QueueLevels", "Motion pipeline queue levels"),
    "servoamp.Session": _obj({
        "connection": {"type": "integer", "minimum": 1},
        "controller_id": {"type": "string"},
        "session_id": {"type": "string"},
        "wire_version": _U32,
        "n_axes": _U32,
        "cycle_period_ns": _U32,
        "clock_hz": _U32,
        "ring_capacity": _U32,
        "realtime_ns": _U64,
    }, "servoamp.Session", "A telemetry connection (HELLO)"),
    # foxglove.Log, as published in Foxglove's schemas (JSON Schema flavour).
    "foxglove.Log": {
        "title": "foxglove.Log",
        "description": "A log message",
        "type": "object",
        "properties": {
            "timestamp": {
                "type": "object", "title": "time",
                "properties": {
                    "sec": {"type": "integer", "minimum": 0},
                    "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999},
                },
                "description": "Timestamp of log message",
            },
            "level": {
                "title": "foxglove.LogLevel", "description": "Log level",
                "oneOf": [
                    {"title": "UNKNOWN", "const": 0}, {"title": "DEBUG", "const": 1},
                    {"title": "INFO", "const": 2}, {"title": "WARNING", "const": 3},
                    {"title": "ERROR", "const": 4}, {"title": "FATAL", "const": 5},
                ],
            },
            "message": {"type": "string", "description": "Log message"},
            "name": {"type": "string", "description": "Process or node name"},
            "file": {"type": "string", "description": "Filename"},
            "line": {"type": "integer", "minimum": 0, "description": "Line number in the file"},
        },
    },
}

TOPIC_SCHEMA = {
    T_CYCLE: "servoamp.Cycle", T_PATH: "servoamp.Path", T_STATS: "servoamp.Stats",
    T_PARAM: "servoamp.ParamChange", T_LOG: "foxglove.Log", T_GAP: "servoamp.Gap",
    T_QUEUES: "servoamp.QueueLevels", T_SESSION: "servoamp.Session",
}


def schema_for_topic(topic: str) -> str:
    if topic.startswith("/servoamp/axis/"):
        return "servoamp.AxisSample"
    return TOPIC_SCHEMA[topic]


class RecordingWriter:
    """An MCAP writer with the servoamp channels, chunked, compressed, indexed.

    The open chunk is closed and handed to the OS (written, not fsynced) as
    soon as any of these holds, so a recorder killed with SIGKILL loses at
    most the messages of that one open chunk:

    * ``flush_interval_ns`` of controller time (message timestamps) passed;
    * ``flush_interval_s`` of host time (time.monotonic) passed since the last
      flush while messages were pending: checked by maybe_flush() and poll(),
      which the recorder calls at least every 0.1 s whatever arrives, so the
      stretches with only PARAM/GAP/STATS/LOG messages are covered too;
    * ``flush_messages`` messages were written since the last flush;
    * the chunk reached ``chunk_size`` bytes (the mcap writer itself).
    """

    def __init__(self, out: IO[bytes], chunk_size: int = 1 << 20,
                 compression: CompressionType = CompressionType.ZSTD,
                 flush_interval_ns: int = 1_000_000_000,
                 flush_interval_s: float | None = None,
                 flush_messages: int = 10_000) -> None:
        self.out = out
        self.writer = Writer(out, chunk_size=chunk_size, compression=compression,
                             index_types=IndexType.ALL, use_chunking=True,
                             use_statistics=True, use_summary_offsets=True,
                             enable_crcs=True)
        self.writer.start(profile=PROFILE, library=LIBRARY)
        self._schema_ids: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._seq: dict[int, int] = {}
        self.flush_interval_ns = flush_interval_ns
        self.flush_interval_s = (flush_interval_s if flush_interval_s is not None
                                 else flush_interval_ns / 1e9)
        self.flush_messages = max(1, flush_messages)
        self._last_flush_ns: int | None = None
        self._last_flush_host = time.monotonic()
        self._flushed_messages = 0
        self.flushes = 0
        self.messages = 0
        self.finished = False

    def channel(self, topic: str) -> int:
        cid = self._channels.get(topic)
        if cid is None:
            sname = schema_for_topic(topic)
            sid = self._schema_ids.get(sname)
            if sid is None:
                sid = self.writer.register_schema(
                    sname, "jsonschema", json.dumps(SCHEMAS[sname]).encode())
                self._schema_ids[sname] = sid
            cid = self.writer.register_channel(topic, "json", sid)
            self._channels[topic] = cid
            self._seq[cid] = 0
        return cid

    def write_raw(self, cid: int, t_ns: int, data: bytes) -> None:
        seq = self._seq[cid]
        self._seq[cid] = seq + 1
        self.writer.add_message(cid, t_ns, data, t_ns, seq & 0xFFFFFFFF)
        self.messages += 1

    def write(self, topic: str, t_ns: int, obj: dict[str, Any]) -> None:
        self.write_raw(self.channel(topic), t_ns,
                       json.dumps(obj, separators=(",", ":")).encode())

    def metadata(self, name: str, data: dict[str, str]) -> None:
        self.writer.add_metadata(name, data)

    def flush(self) -> None:
        """Close the open chunk (if it holds messages) and hand everything to the OS."""
        self.writer.flush()  # type: ignore[no-untyped-call]
        self.out.flush()
        self._flushed_messages = self.messages
        self._last_flush_host = time.monotonic()
        self.flushes += 1

    def maybe_flush(self, t_ns: int | None = None) -> None:
        """After writing: flush when one of the limits (class docstring) is reached.
        t_ns is the controller time of the newest message, None if unknown."""
        pending = self.messages - self._flushed_messages
        if t_ns is not None:
            if self._last_flush_ns is None:
                self._last_flush_ns = t_ns
            elif abs(t_ns - self._last_flush_ns) >= self.flush_interval_ns:
                self._last_flush_ns = t_ns
                if pending:
                    self.flush()
                    return
        if pending >= self.flush_messages:
            self.flush()
        else:
            self.poll()

    def poll(self) -> None:
        """Flush when messages have been pending for flush_interval_s of host time."""
        if self.messages != self._flushed_messages and \
                time.monotonic() - self._last_flush_host >= self.flush_interval_s:
            self.flush()

    def finish(self) -> None:
        if not self.finished:
            self.finished = True
            self.writer.finish()  # type: ignore[no-untyped-call]
            self.out.flush()


# ---- reading -------------------------------------------------------------------

@dataclass
class ReadResult:
    complete: bool  # footer + summary present (a finalized file)
    error: str  # why reading stopped early, "" if it did not


def _iter_streaming(f: IO[bytes], topics: set[str] | None, res: ReadResult,
                    ) -> Iterator[tuple[Channel, Schema | None, int, bytes]]:
    channels: dict[int, Channel] = {}
    schemas: dict[int, Schema] = {}
    try:
        for rec in StreamReader(f, validate_crcs=True).records:
            if isinstance(rec, Schema):
                schemas[rec.id] = rec
            elif isinstance(rec, Channel):
                channels[rec.id] = rec
            elif isinstance(rec, Message):
                ch = channels.get(rec.channel_id)
                if ch is None:
                    raise McapError(f"message on unknown channel {rec.channel_id}")
                if topics is None or ch.topic in topics:
                    yield ch, schemas.get(ch.schema_id), rec.log_time, rec.data
    except (McapError, struct.error, ValueError, EOFError, zlib.error, OSError) as e:
        res.error = f"{type(e).__name__}: {e}"
    except Exception as e:  # noqa: BLE001 - decompressors raise their own types
        res.error = f"{type(e).__name__}: {e}"


def has_footer(path: Path) -> bool:
    with open(path, "rb") as f:
        try:
            f.seek(-8, 2)
        except OSError:
            return False
        return f.read(8) == b"\x89MCAP0\r\n"


def iter_messages(path: Path | str, topics: Iterable[str] | None = None,
                  result: ReadResult | None = None) -> Iterator[tuple[str, int, bytes]]:
    """(topic, log_time, JSON bytes) of every message, in file order.

    A finalized file is read through its index; a file without a footer (the
    recorder was killed) is read record by record up to the last complete,
    CRC-checked chunk, and ``result.error`` says where it stopped.
    """
    for ch, _schema, t, data in _iter_records(path, topics, result):
        yield ch.topic, t, data


def _iter_records(path: Path | str, topics: Iterable[str] | None = None,
                  result: ReadResult | None = None
                  ) -> Iterator[tuple[Channel, Schema | None, int, bytes]]:
    res = result if result is not None else ReadResult(False, "")
    tset = set(topics) if topics is not None else None
    path = Path(path)
    with open(path, "rb") as f:
        if has_footer(path):
            try:
                reader = make_reader(f)
                if reader.get_summary() is not None:
                    res.complete = True
                    for sc, ch, msg in reader.iter_messages(
                            topics=list(tset) if tset is not None else None,
                            log_time_order=False):
                        yield ch, sc, msg.log_time, msg.data
                    return
            except McapError:
                f.seek(0)
        res.complete = False
        f.seek(0)
        yield from _iter_streaming(f, tset, res)


class _ProtobufDecoder:
    """Message classes built from the schemas in the file (FileDescriptorSet)."""

    def __init__(self) -> None:
        self.classes: dict[tuple[str, bytes], Any] = {}

    def decode(self, schema: Schema, data: bytes) -> Any:
        from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

        key = (schema.name, schema.data)
        cls = self.classes.get(key)
        if cls is None:
            pool = descriptor_pool.DescriptorPool()
            fds = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
            for fd in fds.file:
                pool.Add(fd)
            cls = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))
            self.classes[key] = cls
        return cls.FromString(data)


def iter_json(path: Path | str, topics: Iterable[str] | None = None,
              result: ReadResult | None = None) -> Iterator[tuple[str, int, Any]]:
    """(topic, log_time, message as a dict) of every message, in file order,
    for JSON and protobuf recordings alike. For a protobuf recording (one
    /servoamp/cycle message with every axis), the /servoamp/axis/<i> and
    /servoamp/path messages of the JSON recordings are derived from it."""
    from servoamp import pbenc

    want = set(topics) if topics is not None else None
    derive = want is None or T_PATH in want or any(t.startswith("/servoamp/axis/") for t in want)
    read = None if want is None else want | ({T_CYCLE} if derive else set())
    dec = _ProtobufDecoder()
    for ch, schema, t, data in _iter_records(path, read, result):
        if ch.message_encoding != "protobuf" or schema is None:
            if want is None or ch.topic in want:
                yield ch.topic, t, json.loads(data)
            continue
        if schema.name == "servoamp.Cycle":
            c = pbenc.decode_cycle(data)
            axes = c.pop("axes", [])
            if want is None or ch.topic in want:
                yield ch.topic, t, c
            if derive:
                c["axes"] = axes
                for a in pbenc.axis_dicts(c):
                    topic = axis_topic(a["axis"])
                    if want is None or topic in want:
                        yield topic, t, a
                pth = pbenc.path_dict(c)
                if pth is not None and (want is None or T_PATH in want):
                    yield T_PATH, t, pth
            continue
        m = pbenc.to_dict(dec.decode(schema, data))
        if schema.name == "foxglove.Log":
            ts = m.get("timestamp") or {}
            m["timestamp"] = {"sec": ts.get("seconds", 0), "nsec": ts.get("nanos", 0)}
        yield ch.topic, t, m


def read_metadata(path: Path | str) -> list[Metadata]:
    out: list[Metadata] = []
    with open(path, "rb") as f:
        try:
            for rec in StreamReader(f, validate_crcs=False).records:
                if isinstance(rec, Metadata):
                    out.append(rec)
        except Exception:  # noqa: BLE001 - truncated tail
            pass
    return out


def read_schemas(path: Path | str) -> dict[str, tuple[str, dict[str, Any]]]:
    """topic -> (schema name, parsed JSON schema), from the file itself."""
    schemas: dict[int, Schema] = {}
    out: dict[str, tuple[str, dict[str, Any]]] = {}
    with open(path, "rb") as f:
        try:
            for rec in StreamReader(f, validate_crcs=False).records:
                if isinstance(rec, Schema):
                    schemas[rec.id] = rec
                elif isinstance(rec, Channel) and rec.schema_id in schemas:
                    s = schemas[rec.schema_id]
                    out[rec.topic] = (s.name, json.loads(s.data))
        except Exception:  # noqa: BLE001 - truncated tail
            pass
    return out
