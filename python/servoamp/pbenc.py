"""Protobuf encoding of the servoamp channels (schemas/servoamp.proto).

The per-cycle message (servoamp.Cycle) has fixed-width fields only, so a
Cycle with n axes always has the same layout: :func:`cycle_encoder` builds,
once per axis count, one ``struct.Struct`` with the field tags inline and
returns a function that turns a telemetry CYCLE payload into the protobuf
bytes in two struct calls. The low-rate messages use the generated classes
(``schemas/servoamp_pb2.py``).

:func:`to_dict` turns any decoded protobuf message into the dict shape the
JSON channels of ``servoamp record`` have, for ``info`` and ``plot``.
"""

from __future__ import annotations

import struct
from typing import Any, Callable

from google.protobuf import descriptor_pb2
from google.protobuf.message import Message

from servoamp import telemetry as tw
from servoamp.schemas import servoamp_pb2 as pb

EXCHANGE_UNKNOWN = 6

# (field number << 3) | wire type: 0 varint, 1 64-bit, 2 length-delimited, 5 32-bit
_CYCLE_HDR = [
    (1, 1, "Q"),   # cycle, fixed64
    (2, 5, "I"),   # servo_cycle
    (3, 5, "I"),   # t_cycle
    (4, 5, "I"),   # irq_latency_ticks
    (5, 1, "d"),   # irq_latency_ns, double
    (6, 5, "I"),   # wake_latency_ns
    (7, 0, "B"),   # exchange, enum (< 128: one varint byte)
    (8, 5, "I"),   # missed
    (9, 5, "I"),   # servo_status
    (10, 5, "i"),  # result, sfixed32
]
_CMD = [(1, "I"), (2, "i"), (3, "i"), (4, "i")]
_FB = [(1, "I"), (2, "i"), (3, "i"), (4, "i"), (5, "i")]
_CMD_LEN = 5 * len(_CMD)
_FB_LEN = 5 * len(_FB)
_AXIS_LEN = 2 + _CMD_LEN + 2 + _FB_LEN


def file_descriptor_set() -> bytes:
    """The schema data of every servoamp channel (schema encoding "protobuf")."""
    fds = descriptor_pb2.FileDescriptorSet()
    fds.file.append(descriptor_pb2.FileDescriptorProto.FromString(pb.DESCRIPTOR.serialized_pb))
    return fds.SerializeToString()


def cycle_struct_fmt(n_axes: int) -> str:
    fmt = "<"
    for _num, _wt, code in _CYCLE_HDR:
        fmt += "B" + code
    fmt += ("BB" + "BB" + "".join("B" + c for _n, c in _CMD)
            + "BB" + "".join("B" + c for _n, c in _FB)) * n_axes
    return fmt


def cycle_encoder(n_axes: int, tick_ns: float) -> Callable[[bytes | bytearray, int], bytes]:
    """f(buf, off) -> servoamp.Cycle bytes for the CYCLE payload at buf[off:]."""
    src = tw.cycle_struct(n_axes)
    dst = struct.Struct(cycle_struct_fmt(n_axes))
    # v: the wire fields (11 header words, then 9 per axis)
    args = []
    wire_idx = [0, 2, 3, 4, None, 5, None, 7, 8, 9]
    for (num, wt, _code), wi in zip(_CYCLE_HDR, wire_idx):
        args.append(str((num << 3) | wt))
        if num == 5:
            args.append("v[4] * tick_ns")
        elif num == 7:
            args.append(f"v[6] if v[6] < {EXCHANGE_UNKNOWN} else {EXCHANGE_UNKNOWN}")
        else:
            args.append(f"v[{wi}]")
    for i in range(n_axes):
        a = 11 + 9 * i
        args += [str((11 << 3) | 2), str(_AXIS_LEN), str((1 << 3) | 2), str(_CMD_LEN)]
        for k, (num, _c) in enumerate(_CMD):
            args += [str((num << 3) | 5), f"v[{a + k}]"]
        args += [str((2 << 3) | 2), str(_FB_LEN)]
        for k, (num, _c) in enumerate(_FB):
            args += [str((num << 3) | 5), f"v[{a + 4 + k}]"]
    code = ("def enc(buf, off):\n"
            "    v = unpack_from(buf, off)\n"
            f"    return pack({', '.join(args)})\n")
    ns: dict[str, Any] = {"unpack_from": src.unpack_from, "pack": dst.pack, "tick_ns": tick_ns}
    exec(compile(code, f"<servoamp.pbenc cycle {n_axes}>", "exec"), ns)
    enc: Callable[[bytes | bytearray, int], bytes] = ns["enc"]
    return enc


# ---- decoding to the JSON shapes ----------------------------------------------------

def to_dict(msg: Message) -> dict[str, Any]:
    """Every field (unset scalars as their defaults; unset `optional` as None;
    enums as numbers; 64-bit integers as int; maps as dicts)."""
    out: dict[str, Any] = {}
    for f in msg.DESCRIPTOR.fields:
        v = getattr(msg, f.name)
        if f.message_type is not None and f.message_type.GetOptions().map_entry:
            vf = f.message_type.fields_by_name["value"]
            out[f.name] = {k: (to_dict(x) if vf.message_type is not None else x)
                           for k, x in v.items()}
        elif f.is_repeated:
            out[f.name] = [to_dict(x) if f.message_type is not None else x for x in v]
        elif f.message_type is not None:
            out[f.name] = to_dict(v) if msg.HasField(f.name) else None
        elif f.has_presence and not msg.HasField(f.name):
            out[f.name] = None
        else:
            out[f.name] = v
    return out


def cycle_dict(d: dict[str, Any]) -> dict[str, Any]:
    """A decoded servoamp.Cycle as the JSON /servoamp/cycle message."""
    code = d.get("exchange", 0)
    d["exchange_code"] = code
    d["exchange"] = tw.exchange_name(code)
    return d


def axis_dicts(c: dict[str, Any]) -> list[dict[str, Any]]:
    """The JSON /servoamp/axis/<i> messages of one decoded Cycle."""
    return [{"cycle": c["cycle"], "axis": i, "command": a["command"], "feedback": a["feedback"]}
            for i, a in enumerate(c.get("axes", []))]


def path_dict(c: dict[str, Any]) -> dict[str, Any] | None:
    ax = c.get("axes", [])
    if len(ax) < 2:
        return None
    return {"cycle": c["cycle"],
            "command": {"x": ax[0]["command"]["target_pos"], "y": ax[1]["command"]["target_pos"]},
            "actual": {"x": ax[0]["feedback"]["actual_pos"], "y": ax[1]["feedback"]["actual_pos"]}}


_HDR_LEN = sum(1 + {"Q": 8, "d": 8, "I": 4, "i": 4, "B": 1}[c] for _n, _w, c in _CYCLE_HDR)
_FAST: dict[int, tuple[struct.Struct, tuple[int, ...], list[int]]] = {}
_CYCLE_KEYS = ("cycle", "servo_cycle", "t_cycle", "irq_latency_ticks", "irq_latency_ns",
               "wake_latency_ns", "exchange", "missed", "servo_status", "result")
_CMD_KEYS = ("control_word", "target_pos", "vel_ff", "torque_offset")
_FB_KEYS = ("status_word", "actual_pos", "actual_vel", "current", "following_error")


def _fast(n: int) -> tuple[struct.Struct, tuple[int, ...], list[int]]:
    f = _FAST.get(n)
    if f is None:
        s = struct.Struct(cycle_struct_fmt(n))
        tags: list[int] = [(num << 3) | wt for num, wt, _c in _CYCLE_HDR]
        for _i in range(n):
            tags += [(11 << 3) | 2, _AXIS_LEN, (1 << 3) | 2, _CMD_LEN]
            tags += [(num << 3) | 5 for num, _c in _CMD]
            tags += [(2 << 3) | 2, _FB_LEN]
            tags += [(num << 3) | 5 for num, _c in _FB]
        # positions of the tags in the unpacked tuple
        pos: list[int] = []
        k = 0
        for _num, _wt, _c in _CYCLE_HDR:
            pos.append(k)
            k += 2
        for _i in range(n):
            pos += [k, k + 1, k + 2, k + 3]
            k += 4
            for _f in _CMD:
                pos.append(k)
                k += 2
            pos += [k, k + 1]
            k += 2
            for _f in _FB:
                pos.append(k)
                k += 2
        f = (s, tuple(tags), pos)
        _FAST[n] = f
    return f


def decode_cycle(data: bytes) -> dict[str, Any]:
    """A servoamp.Cycle as the JSON /servoamp/cycle dict (plus ``axes``): the
    fixed layout :func:`cycle_encoder` writes in one struct call, anything
    else through the protobuf runtime."""
    n, r = divmod(len(data) - _HDR_LEN, 2 + _AXIS_LEN)
    if r == 0 and 0 <= n <= 64:
        s, tags, pos = _fast(n)
        v = s.unpack(data)
        if tuple(v[i] for i in pos) == tags:
            d = {k: v[2 * j + 1] for j, k in enumerate(_CYCLE_KEYS)}
            axes = []
            k = 2 * len(_CYCLE_HDR)
            for _i in range(n):
                k += 4
                cmd = {key: v[k + 2 * j + 1] for j, key in enumerate(_CMD_KEYS)}
                k += 2 * len(_CMD) + 2
                fb = {key: v[k + 2 * j + 1] for j, key in enumerate(_FB_KEYS)}
                k += 2 * len(_FB)
                axes.append({"command": cmd, "feedback": fb})
            d["axes"] = axes
            return cycle_dict(d)
    return cycle_dict(to_dict(pb.Cycle.FromString(data)))
