"""Fuzzing the Python telemetry frame decoder and the recorder behind it (issue 13).

Three targets, each a property checked on inputs that Hypothesis generates
(random bytes, and valid frames of every type with random fields, mutated:
truncated, bytes flipped, length/count words overwritten, bytes inserted,
spliced), fed in random-sized pieces:

* ``decoder``: servoamp.telemetry.decode(type, payload, n_axes) returns or
  raises ProtocolError, the module's one documented error, and nothing else;
* ``stream``: FrameSplitter + decode over a byte stream: only ProtocolError,
  every frame consumes at least its 8-byte header (so the loop ends), and
  the splitter's buffer holds only the unconsumed tail;
* ``recorder``: the recorder's session (servoamp.record._Session.process and
  mcapio.RecordingWriter into memory): raises nothing but the framing
  ProtocolError (which record() answers by reconnecting), every bad frame
  is counted, and the MCAP it writes reads back with the mcap reader as
  strict JSON (no NaN) that validates against the file's own schemas.

Each example also runs under a watchdog (SIGALRM, HANG_S seconds) so a loop
shows as a finding instead of a stuck run; the structural checks above are
what the short pytest run relies on.

    .venv/bin/python tests/fuzz/fuzz_telemetry.py --seconds 300 [--target all]

prints executions and findings per target (exit status 1 on a finding; the
shrunk input is printed). tests/fuzz/test_telemetry_decoder.py is the short,
derandomized run in the test suite.
"""

from __future__ import annotations

import argparse
import io
import json
import logging
import signal
import struct
import sys
import time
import traceback
from pathlib import Path
from types import FrameType
from typing import Any, Callable

_TOP = Path(__file__).resolve().parents[2]
if str(_TOP / "python") not in sys.path:
    sys.path.insert(0, str(_TOP / "python"))

import jsonschema  # noqa: E402
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
from hypothesis.errors import HypothesisException  # noqa: E402
from mcap.reader import make_reader  # noqa: E402
from mcap.writer import CompressionType  # noqa: E402

from servoamp import mcapio  # noqa: E402
from servoamp import telemetry as tw  # noqa: E402
from servoamp.record import RecordResult, _Session  # noqa: E402

HANG_S = 20
# the recorder reports every bad frame on this logger: quiet here, counted instead
logging.getLogger("servoamp.record").setLevel(logging.CRITICAL)
U64 = st.integers(0, 2**64 - 1)
U32 = st.integers(0, 2**32 - 1)
I32 = st.integers(-(2**31), 2**31 - 1)
SMALL_U64 = st.integers(0, 10_000)
NAME = st.text(max_size=20).map(lambda s: s.encode()[:15].decode("utf-8", "ignore"))
INTERESTING_U32 = [0, 1, 2, 7, 8, 9, 63, 64, 65, 480, 481, 0x7FFFFFFF, 0x80000000, 0xFFFFFFFF,
                   1 << 20, (1 << 20) + 1]

# ---- valid frames of every type, random fields --------------------------------------


@st.composite
def hello_frame(draw: st.DrawFn) -> bytes:
    return tw.encode_hello(draw(st.integers(1, 8)), draw(U64), draw(U64), draw(U64),
                           draw(U32), draw(U32), draw(U32), draw(NAME))


@st.composite
def cycle_frame(draw: st.DrawFn) -> bytes:
    n = draw(st.integers(0, 8))
    axes = [tuple([draw(U32)] + [draw(I32) for _ in range(3)] + [draw(U32)]
                  + [draw(I32) for _ in range(4)]) for _ in range(n)]
    return tw.encode_cycle(n, draw(st.one_of(SMALL_U64, U64)), draw(U64),
                           draw(st.integers(0, 7)), axes)


@st.composite
def stats_frame(draw: st.DrawFn) -> bytes:
    counters = draw(st.dictionaries(NAME, U64, max_size=4))
    return tw.encode_stats(draw(U64), draw(U64), draw(st.booleans()), counters)


@st.composite
def param_frame(draw: st.DrawFn) -> bytes:
    return tw.encode_param(draw(U64), draw(U64), draw(U32), draw(st.floats()), draw(NAME),
                           draw(NAME), draw(st.integers(0, 5)))


@st.composite
def log_frame(draw: st.DrawFn) -> bytes:
    text = draw(st.text(max_size=120))
    return tw.encode_log(draw(U64), draw(U64), text[:120], draw(st.integers(0, 7)),
                         draw(NAME))


@st.composite
def gap_frame(draw: st.DrawFn) -> bytes:
    return tw.encode_gap(draw(U64), draw(st.one_of(SMALL_U64, U64)),
                         draw(st.one_of(SMALL_U64, U64)), draw(U64), draw(st.integers(0, 7)))


@st.composite
def queues_frame(draw: st.DrawFn) -> bytes:
    levels = draw(st.dictionaries(NAME, st.tuples(U32, U32), max_size=9))
    return tw.encode_queues(draw(U64), levels)


@st.composite
def other_frame(draw: st.DrawFn) -> bytes:
    typ = draw(st.sampled_from([0, tw.MSG_AUTH, 9, 0xFFFF]))
    return tw.encode_frame(typ, draw(st.binary(max_size=64)), draw(st.sampled_from([0, 1])))


VALID = st.one_of(hello_frame(), cycle_frame(), stats_frame(), param_frame(), log_frame(),
                  gap_frame(), queues_frame(), other_frame())


@st.composite
def mutated(draw: st.DrawFn, base: st.SearchStrategy[bytes] = VALID) -> bytes:
    b = bytearray(draw(base))
    for _ in range(draw(st.integers(0, 3))):
        kind = draw(st.integers(0, 5))
        if kind == 0 and b:      # truncate
            del b[draw(st.integers(0, len(b) - 1)):]
        elif kind == 1 and b:    # flip a byte
            i = draw(st.integers(0, len(b) - 1))
            b[i] ^= draw(st.integers(1, 255))
        elif kind == 2 and len(b) >= 4:  # an interesting u32 (lengths, counts, types)
            i = draw(st.integers(0, len(b) - 4))
            struct.pack_into("<I", b, i, draw(st.sampled_from(INTERESTING_U32)))
        elif kind == 3:          # insert bytes
            i = draw(st.integers(0, len(b)))
            b[i:i] = draw(st.binary(min_size=1, max_size=16))
        elif kind == 4 and len(b) >= 8:  # the frame header's length word
            struct.pack_into("<I", b, 4, draw(st.sampled_from(INTERESTING_U32
                                                              + [max(0, len(b) - 8 - 1)])))
        elif kind == 5 and b:    # NaN/inf into an f64-sized slot
            i = draw(st.integers(0, max(0, len(b) - 8)))
            b[i:i + 8] = struct.pack("<d", draw(st.sampled_from(
                [float("nan"), float("inf"), -float("inf")])))
    return bytes(b)


FRAME = st.one_of(VALID, mutated(), st.binary(max_size=200))
STREAM = st.one_of(st.lists(FRAME, max_size=12).map(b"".join), st.binary(max_size=2048))


@st.composite
def pieces(draw: st.DrawFn, hello_first: bool = False) -> list[bytes]:
    """A stream cut at random points, as recv() delivers it; hello_first:
    mostly led by a valid HELLO (as a server sends it), so that the cycles
    after it are decoded and written rather than refused."""
    data = draw(STREAM)
    if hello_first and draw(st.integers(0, 3)):
        data = draw(hello_frame()) + data
    cuts = sorted(draw(st.lists(st.integers(0, len(data)), max_size=6)))
    out, prev = [], 0
    for c in cuts + [len(data)]:
        out.append(data[prev:c])
        prev = c
    return out


# ---- the properties ---------------------------------------------------------------


class Hang(Exception):
    pass


def _alarm(_s: int, _f: FrameType | None) -> None:
    raise Hang(f"an example ran longer than {HANG_S} s")


def _guarded(fn: Callable[..., None]) -> Callable[..., None]:
    def run(*a: Any) -> None:
        old = signal.signal(signal.SIGALRM, _alarm)
        signal.alarm(HANG_S)
        try:
            fn(*a)
        finally:
            signal.alarm(0)
            signal.signal(signal.SIGALRM, old)
    return run


EXPECT = {tw.MSG_HELLO: tw.Hello, tw.MSG_CYCLE: tuple, tw.MSG_STATS: tw.Stats,
          tw.MSG_PARAM: tw.Param, tw.MSG_LOG: tw.Log, tw.MSG_GAP: tw.Gap,
          tw.MSG_QUEUES: tw.Queues}


def check_decoder(frame: bytes, n_axes: int) -> None:
    if len(frame) < 8:
        typ, payload = (frame[0] if frame else 0), frame
    else:
        typ, payload = tw.FRAME.unpack_from(frame)[0], frame[8:]
    try:
        m = tw.decode(typ, payload, n_axes)
    except tw.ProtocolError:
        return
    want = EXPECT.get(typ)
    assert (m is None) if want is None else isinstance(m, want), (typ, m)


def check_stream(chunks: list[bytes], n_axes: int) -> None:
    sp = tw.FrameSplitter()
    fed = 0
    consumed = 0
    for c in chunks:
        sp.feed(c)
        fed += len(c)
        n = 0
        try:
            for typ, off, ln in sp.frames():
                n += 1
                assert n <= fed // 8, "more frames than 8-byte headers"
                assert off >= 8 and off + ln <= len(sp.buf)
                consumed += 8 + ln
                try:
                    tw.decode(typ, bytes(sp.buf[off:off + ln]), n_axes)
                except tw.ProtocolError:
                    pass
        except tw.ProtocolError:
            return  # framing lost: the reader drops the connection
        assert len(sp.buf) == fed - consumed


def _no_constant(s: str) -> Any:
    raise ValueError(f"non-standard JSON constant {s}")


_VALIDATORS: dict[str, Any] = {}


def _validator(schema_name: str) -> Any:
    v = _VALIDATORS.get(schema_name)
    if v is None:
        v = _VALIDATORS[schema_name] = jsonschema.Draft202012Validator(
            mcapio.SCHEMAS[schema_name])
    return v


def check_recorder(chunks: list[bytes], _n_axes: int = 0) -> None:
    res = RecordResult(path="<fuzz>")
    out = io.BytesIO()
    w = mcapio.RecordingWriter(out, chunk_size=4096, compression=CompressionType.NONE,
                               flush_messages=64)
    sess = _Session(w, res)
    sess.new_connection()
    sp = tw.FrameSplitter()
    for c in chunks:
        sp.feed(c)
        try:
            sess.process(sp.buf, sp.frames())
        except tw.ProtocolError:
            break  # framing lost: record() counts it and reconnects
    assert sum(res.bad_frames_by_type.values()) == res.bad_frames
    w.finish()
    reader = make_reader(io.BytesIO(out.getvalue()))
    n = 0
    for _s, ch, msg in reader.iter_messages(log_time_order=False):
        obj = json.loads(msg.data, parse_constant=_no_constant)
        _validator(mcapio.schema_for_topic(ch.topic)).validate(obj)
        n += 1
    assert n == w.messages, (n, w.messages)


TARGETS: dict[str, tuple[Callable[..., None], Any]] = {
    "decoder": (check_decoder, (FRAME, st.integers(0, 9))),
    "stream": (check_stream, (pieces(), st.integers(0, 9))),
    "recorder": (check_recorder, (pieces(hello_first=True),)),
}


def make_test(target: str, counter: list[int]) -> Callable[[], None]:
    fn, strategies = TARGETS[target]
    guarded = _guarded(fn)

    @given(st.tuples(*strategies))
    def prop(a: tuple[Any, ...]) -> None:
        counter[0] += 1
        guarded(*a)

    return prop


# ---- the long run -------------------------------------------------------------------


def run(target: str, seconds: float, batch: int = 200) -> tuple[int, list[str]]:
    """Batches of `batch` random examples until `seconds` pass; a finding
    (Hypothesis shrinks it) ends the target."""
    counter = [0]
    findings: list[str] = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        test = make_test(target, counter)
        test = settings(max_examples=batch, deadline=None, database=None,
                        suppress_health_check=list(HealthCheck))(test)
        try:
            test()
        except HypothesisException:
            raise  # the harness is wrong, not the code under test
        except Exception:  # noqa: BLE001 - every failure is a finding to report
            findings.append(traceback.format_exc())
            break
    return counter[0], findings


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=60.0, help="total, split over the targets")
    ap.add_argument("--target", choices=[*TARGETS, "all"], default="all")
    args = ap.parse_args(argv)
    targets = list(TARGETS) if args.target == "all" else [args.target]
    total_findings = 0
    t0 = time.monotonic()
    for t in targets:
        s0 = time.monotonic()
        n, findings = run(t, args.seconds / len(targets))
        dt = time.monotonic() - s0
        total_findings += len(findings)
        print(f"telemetry fuzz {t}: {n} executions in {dt:.0f} s ({n / dt:.0f}/s), "
              f"{len(findings)} findings", flush=True)
        for f in findings:
            print(f)
    print(f"telemetry fuzz: {time.monotonic() - t0:.0f} s, {total_findings} findings")
    return 1 if total_findings else 0


if __name__ == "__main__":
    sys.exit(main())
