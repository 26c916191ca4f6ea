"""The recorder against a misbehaving telemetry server (issue 13, finding 9).

A real `servoamp record` process against a scripted server on 127.0.0.1
that speaks the wire protocol (AUTH with a token, HELLO, then frames):

* short and garbled frames of every type are counted and skipped, with a
  message on stderr and no traceback; the recording goes on, also across a
  frame header that loses the framing (reconnect) and ends cleanly without
  reconnect;
* a recorder that receives only PARAM/LOG/GAP/STATS frames (no cycle
  timestamps: a stop or a recovery) and is then SIGKILLed leaves them on
  disk, up to the bound of docs/recording.md (host-time flush, message-count
  flush), read back by the Python mcap stream reader and by @mcap/core.

The polling loops below wait for the recorder to get somewhere; their
deadline only turns a hang into a failure, it is not what is tested.
"""

from __future__ import annotations

import json
import math
import os
import signal
import struct
import subprocess
import time
from pathlib import Path
from typing import Any, Callable

import jsonschema
import pytest

from recorder_helpers import ScriptedServer, node_verify, servoamp_cmd
from servoamp import info, mcapio
from servoamp import telemetry as tw

ENV = dict(os.environ, PYTHONUNBUFFERED="1")
TOKEN = b"hostile-test-token-0123"
N_AXES = 2
T0 = 5_000_000_000
SESSION = 0x5EED


def _t(cycle: int) -> int:
    return T0 + cycle * 1_000_000


def _cycles(a: int, b: int) -> bytes:
    return b"".join(tw.encode_cycle(N_AXES, c, _t(c),
                                    axes=[(1, c, 0, 0, 1, c - 1, 0, 0, 1)] * N_AXES)
                    for c in range(a, b))


def _bad_frames() -> list[tuple[str, bytes]]:
    """(type name, frame) for short and garbled frames of every type."""
    f = tw.encode_frame
    good_param = tw.encode_param(_t(10), 10, 7, 1.0, "pos_kp")[8:]
    good_log = tw.encode_log(_t(10), 10, "ok")[8:]
    good_stats = tw.encode_stats(_t(10), 10)[8:]
    good_queues = tw.encode_queues(_t(10), {"q": (1, 8)})[8:]
    bad_magic = bytearray(tw.encode_hello(N_AXES, SESSION)[8:])
    bad_magic[0] ^= 0xFF
    out = [
        ("PARAM", f(tw.MSG_PARAM, good_param[:12])),          # the struct.error of the issue
        ("PARAM", f(tw.MSG_PARAM, b"")),
        ("PARAM", f(tw.MSG_PARAM, good_param[:20] + struct.pack("<I", 9) + good_param[24:])),
        ("PARAM", f(tw.MSG_PARAM, good_param[:24] + struct.pack("<d", math.nan)
                    + good_param[32:])),
        ("GAP", f(tw.MSG_GAP, tw.encode_gap(_t(10), 1, 2, 1, 1)[8:8 + 39])),
        ("GAP", f(tw.MSG_GAP, tw.encode_gap(_t(10), 1, 2, 1, 77)[8:])),
        ("STATS", f(tw.MSG_STATS, good_stats[:50])),
        ("STATS", f(tw.MSG_STATS, good_stats[:96] + struct.pack("<I", 1000) + good_stats[100:])),
        ("LOG", f(tw.MSG_LOG, good_log[:20])),
        ("LOG", f(tw.MSG_LOG, good_log[:20] + struct.pack("<I", 400) + good_log[24:])),
        ("QUEUES", f(tw.MSG_QUEUES, good_queues[:8])),
        ("QUEUES", f(tw.MSG_QUEUES, good_queues[:8] + struct.pack("<I", 9) + good_queues[12:])),
        ("HELLO", f(tw.MSG_HELLO, bytes(bad_magic[:40]))),
        ("HELLO", f(tw.MSG_HELLO, bytes(bad_magic))),
        ("CYCLE", f(tw.MSG_CYCLE, _cycles(10, 11)[8:8 + 60])),
        ("CYCLE", f(tw.MSG_CYCLE, b"")),
    ]
    return out


def _valid_events(k: int) -> bytes:
    """One valid PARAM, LOG, GAP (an event: lost 0), STATS and QUEUES, numbered k."""
    t = _t(20) + k
    return (tw.encode_param(t, 20, 7, float(k), "pos_kp", "1/s")
            + tw.encode_log(t, 20, f"line {k}", level=3, source="rpu_app")
            + tw.encode_gap(t, 20, 20, 0, 4)
            + tw.encode_stats(t, 20, counters={"k": k})
            + tw.encode_queues(t, {"blocks": (k, 64)}))


def _record(port: int, out: Path, tmp: Path, *extra: str) -> subprocess.Popen[str]:
    tok = tmp / "token"
    tok.write_bytes(TOKEN + b"\n")
    return subprocess.Popen(servoamp_cmd("record", "--connect", f"127.0.0.1:{port}", "-o",
                                         str(out), "--json", "--token-file", str(tok), *extra),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV)


def _wait_for(cond: Callable[[], bool], rp: subprocess.Popen[str], what: str,
              limit: float = 90.0) -> None:
    end = time.monotonic() + limit
    while not cond():
        if rp.poll() is not None:
            so, se = rp.communicate()
            pytest.fail(f"recorder exited ({rp.returncode}) before {what}:\n{so}\n{se}")
        if time.monotonic() > end:
            pytest.fail(f"not on disk after {limit:.0f} s: {what}")
        time.sleep(0.1)


def _on_disk(out: Path) -> list[tuple[str, int, Any]]:
    if not out.exists():
        return []
    return list(mcapio.iter_json(out))


@pytest.mark.parametrize("reconnect", [True, False], ids=["reconnect", "no_reconnect"])
def test_bad_frames_counted_and_skipped(tmp_path: Path, reconnect: bool,
                                        node_ready: None) -> None:
    bad = _bad_frames()
    conn1 = tw.encode_hello(N_AXES, SESSION, t_ns=T0) + _cycles(0, 10)
    for k, (_name, frame) in enumerate(bad):
        conn1 += frame + _valid_events(k)
    conn1 += _cycles(10, 20)
    # a header announcing 2 GiB: the framing is lost (then garbage that must not be read)
    conn1 += tw.FRAME.pack(tw.MSG_LOG, 0, 1 << 31) + b"\xff" * 100
    conn2 = (tw.encode_hello(N_AXES, SESSION, t_ns=_t(20)) + _cycles(20, 30)
             + tw.encode_param(_t(29), 29, 8, 2.5, "after_reconnect")
             + tw.encode_stats(_t(29), 29, final=True))
    srv = ScriptedServer([conn1, conn2] if reconnect else [conn1], token=TOKEN)
    out = tmp_path / "bad.mcap"
    rp = _record(srv.port, out, tmp_path, "--flush-interval", "0.2",
                 *([] if reconnect else ["--no-reconnect"]))
    try:
        if reconnect:
            def all_there() -> bool:
                return any(tp == mcapio.T_PARAM and m["name"] == "after_reconnect"
                           for tp, _ts, m in _on_disk(out))
            _wait_for(all_there, rp, "the second connection's frames")
            rp.send_signal(signal.SIGINT)
        so, se = rp.communicate(timeout=60)
    finally:
        if rp.poll() is None:
            rp.kill()
            rp.communicate()
        srv.close()
    assert srv.auth_failed == 0
    assert rp.returncode == 0, se
    assert "Traceback" not in se, se
    r = json.loads(so)
    n_bad = len(bad) + 1  # + the frame that lost the framing
    by_type: dict[str, int] = {}
    for name, _f in bad:
        by_type[name] = by_type.get(name, 0) + 1
    by_type["LOG"] += 1
    assert r["bad_frames"] == n_bad and r["bad_frames_by_type"] == by_type, r
    assert r["stopped_by"] == ("signal" if reconnect else "protocol_error")
    assert r["connections"] == (2 if reconnect else 1)
    # stderr: one line per bad frame, saying which and why, and the total
    assert "bad PARAM frame (12 bytes) after cycle 9 skipped: PARAM of 12 bytes" in se, se
    assert "GAP reason 77" in se and "PARAM value nan" in se and "bad magic" in se, se
    assert "framing lost" in se, se
    assert f"{n_bad} bad frames skipped" in se, se

    last = 29 if reconnect else 19
    msgs = list(mcapio.iter_json(out))
    assert [m["cycle"] for tp, _ts, m in msgs if tp == mcapio.T_CYCLE] == list(range(last + 1))
    params = [m for tp, _ts, m in msgs if tp == mcapio.T_PARAM]
    assert [p["value"] for p in params[:len(bad)]] == [float(k) for k in range(len(bad))]
    assert len([1 for tp, _ts, _m in msgs if tp == mcapio.T_LOG]) == len(bad)
    assert len([1 for tp, _ts, _m in msgs if tp == mcapio.T_QUEUES]) == len(bad)
    schemas = mcapio.read_schemas(out)
    for tp, _ts, m in msgs:  # nothing garbled reached the file
        jsonschema.validate(m, schemas[tp][1])
    meta = {m.name: m.metadata for m in mcapio.read_metadata(out)}
    assert meta["servoamp.recording"]["bad_frames"] == str(n_bad)
    assert json.loads(meta["servoamp.recording"]["bad_frames_by_type"]) == by_type
    s = info.summarize(out)
    assert s["complete"] and s["bad_frames"] == n_bad
    js = node_verify(out)
    assert js["error"] is None and js["json_errors"] == 0
    assert js["cycles"] == {"count": last + 1, "first": 0, "last": last, "non_increasing": 0}


@pytest.mark.parametrize("bound", ["host_time", "message_count"])
def test_sigkill_keeps_event_only_stretch(tmp_path: Path, bound: str, node_ready: None) -> None:
    """A few cycles, then only events (a stopped or recovering controller),
    then SIGKILL. host_time: --flush-interval 0.3, every event must reach the
    disk (the old recorder flushed on cycle timestamps only: nothing did).
    message_count: the interval is an hour, --flush-messages 10: all but at
    most 9 messages must reach the disk."""
    k_events = 40
    script = (tw.encode_hello(N_AXES, SESSION, t_ns=T0) + _cycles(0, 5)
              + b"".join(_valid_events(k) for k in range(k_events)))
    total = 1 + 5 * (2 + N_AXES) + 5 * k_events  # session + cycles + events
    srv = ScriptedServer([script], token=TOKEN)
    out = tmp_path / "kill.mcap"
    if bound == "host_time":
        extra, need = ["--flush-interval", "0.3"], total
    else:
        extra, need = ["--flush-interval", "3600", "--flush-messages", "10"], total - 9
    rp = _record(srv.port, out, tmp_path, *extra)
    try:
        _wait_for(lambda: len(_on_disk(out)) >= need, rp,
                  f"{need} of the {total} messages")
        rp.kill()
        rp.communicate(timeout=30)
    finally:
        if rp.poll() is None:
            rp.kill()
            rp.communicate()
        srv.close()
    assert rp.returncode == -signal.SIGKILL
    assert not mcapio.has_footer(out)
    res = mcapio.ReadResult(False, "")
    msgs = list(mcapio.iter_json(out, None, res))
    assert not res.complete
    assert need <= len(msgs) <= total
    # a prefix of what was sent, in order: no hole before the last chunk on disk
    params = [m["value"] for tp, _ts, m in msgs if tp == mcapio.T_PARAM]
    assert params == [float(k) for k in range(len(params))]
    if bound == "host_time":
        assert len(params) == k_events
    counts: dict[str, int] = {}
    for tp, _ts, _m in msgs:
        counts[tp] = counts.get(tp, 0) + 1
    js = node_verify(out, stream=True)
    assert not js["complete"] and js["by_topic"] == counts and js["json_errors"] == 0
