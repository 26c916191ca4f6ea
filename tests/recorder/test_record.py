"""servoamp record / info / plot against the real telem_feed on 127.0.0.1,
read back by the Python MCAP reader and by the TypeScript @mcap/core."""

from __future__ import annotations

import json
import os
import sys
import signal
import struct
import subprocess
import threading
import time
from pathlib import Path
from typing import Any

import jsonschema
import pytest
from mcap.reader import make_reader

from recorder_helpers import TOP, Feed, free_port, node_verify, servoamp_cmd
from servoamp import info, mcapio, plot
from servoamp.record import record

ENV = dict(os.environ, PYTHONUNBUFFERED="1")


def _feed_args(cycles: int, axes: int = 8, rate: int = 1000, **kw: str) -> list[str]:
    a = ["--cycles", str(cycles), "--axes", str(axes), "--rate", str(rate), "--wait-clients", "1"]
    for k, v in kw.items():
        a += ["--" + k.replace("_", "-"), v]
    return a


@pytest.fixture(scope="module")
def rec(feed_bin: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """One 2 s recording (8 axes, 1 kHz) shared by the read-back tests."""
    out = tmp_path_factory.mktemp("rec") / "run.mcap"
    feed = Feed(feed_bin, *_feed_args(2000, param_every="600", log_every="400",
                                      queues_every="20", restart_at="1000"))
    try:
        res = record("127.0.0.1", feed.port, out, duration=30, reconnect=False)
        fres = feed.result()
    finally:
        feed.kill()
    return {"path": out, "res": res, "feed": fres}


def test_every_cycle_recorded(rec: dict[str, Any]) -> None:
    res, fres = rec["res"], rec["feed"]
    print(f"recorded {res.cycles} cycles, {res.messages} messages, CPU {res.cpu_s:.2f} s "
          f"for {res.wall_s:.2f} s")
    assert fres["pushed"] == fres["sent"] == 2000 and fres["dropped"] == 0
    assert res.cycles == fres["sent"]
    assert (res.first_cycle, res.last_cycle) == (0, 1999)
    assert res.stopped_by == "eof" and res.connections == 1
    assert res.bad_frames == 0  # every frame of the real server decodes
    assert [g["reason"] for g in res.gaps] == ["controller_restart"]
    cycles = [m["cycle"] for _t, _tt, m in mcapio.iter_json(rec["path"], [mcapio.T_CYCLE])]
    assert cycles == list(range(2000))


def test_schemas_valid_and_values_consistent(rec: dict[str, Any]) -> None:
    path = rec["path"]
    schemas = mcapio.read_schemas(path)
    topics = set(schemas)
    assert {mcapio.T_CYCLE, mcapio.T_PATH, mcapio.T_STATS, mcapio.T_PARAM, mcapio.T_LOG,
            mcapio.T_GAP, mcapio.T_QUEUES, mcapio.T_SESSION} <= topics
    assert {mcapio.axis_topic(i) for i in range(8)} <= topics
    assert schemas[mcapio.T_LOG][0] == "foxglove.Log"
    validators = {}
    for topic, (_name, sch) in schemas.items():
        jsonschema.Draft202012Validator.check_schema(sch)
        validators[topic] = jsonschema.Draft202012Validator(sch)
    per_cycle: dict[int, dict[str, Any]] = {}
    counts: dict[str, int] = {}
    last_t: dict[str, int] = {}
    for topic, t, m in mcapio.iter_json(path):
        counts[topic] = counts.get(topic, 0) + 1
        if counts[topic] <= 400:  # every rare message, the first 400 of each per-cycle one
            validators[topic].validate(m)
        assert t >= last_t.get(topic, 0)  # controller clock, monotonic per channel
        last_t[topic] = t
        if topic.startswith("/servoamp/axis/"):
            fb, cmd = m["feedback"], m["command"]
            assert fb["following_error"] == cmd["target_pos"] - fb["actual_pos"]
            per_cycle.setdefault(m["cycle"], {})[m["axis"]] = (cmd["target_pos"], fb["actual_pos"])
        elif topic == mcapio.T_PATH:
            per_cycle.setdefault(m["cycle"], {})["path"] = m
        elif topic == mcapio.T_CYCLE:
            assert m["irq_latency_ns"] == pytest.approx(m["irq_latency_ticks"] * 10.0)
            exp = "stale" if m["cycle"] % 997 == 5 else \
                "missed" if m["cycle"] % 2003 == 7 else "fresh"
            assert m["exchange"] == exp
    for cyc, d in per_cycle.items():
        p = d["path"]
        assert (p["command"]["x"], p["actual"]["x"]) == d[0], cyc
        assert (p["command"]["y"], p["actual"]["y"]) == d[1], cyc
    assert counts[mcapio.T_PARAM] == 3 and counts[mcapio.T_QUEUES] == 100


def test_read_by_typescript_mcap(rec: dict[str, Any], node_ready: None) -> None:
    path = rec["path"]
    py_counts: dict[str, int] = {}
    for topic, _t, _d in mcapio.iter_messages(path):
        py_counts[topic] = py_counts.get(topic, 0) + 1
    for stream in (False, True):
        js = node_verify(path, stream=stream)
        assert js["error"] is None and js["complete"] is True
        assert js["by_topic"] == py_counts
        assert js["json_errors"] == 0
        assert js["cycles"] == {"count": 2000, "first": 0, "last": 1999, "non_increasing": 0}
        assert js["library"] == "servoamp"
        assert set(js["encodings"].values()) == {"json"}
        if not stream:
            assert js["compression"] == ["zstd"] and js["chunks"] >= 1
            assert js["statistics_message_count"] == sum(py_counts.values())


def test_info_numbers(rec: dict[str, Any]) -> None:
    p = subprocess.run(servoamp_cmd("info", str(rec["path"]), "--json"), capture_output=True,
                       text=True, timeout=60, env=ENV)
    assert p.returncode == 0, p.stderr
    s = json.loads(p.stdout)
    assert s["complete"] and s["cycles"] == 2000 and s["n_axes"] == 8
    assert s["controller_id"] == "telem_feed" and s["cycle_period_ns"] == 1_000_000
    # the span of the cycles' log times, read back with the mcap package's
    # own reader (not servoamp's): the feed stamps each cycle when it sends
    # it, so the span depends on the host's load, not only on the rate
    with open(rec["path"], "rb") as f:
        times = [m.log_time for _s, ch, m in make_reader(f).iter_messages() if ch.topic == mcapio.T_CYCLE]
    assert len(times) == 2000
    assert s["duration_s"] == pytest.approx((max(times) - min(times)) / 1e9, abs=1e-9)
    stale = sum(1 for c in range(2000) if c % 997 == 5)
    missed = sum(1 for c in range(2000) if c % 2003 == 7 and c % 997 != 5)
    assert s["exchange"] == {"fresh": 2000 - stale - missed, "stale": stale, "missed": missed}
    assert s["missed"] == missed
    assert [(c["cycle"], c["name"], c["value"]) for c in s["parameter_changes"]] == \
        [(600, "pos_kp", 61.0), (1200, "pos_kp", 62.0), (1800, "pos_kp", 63.0)]
    assert [(g["reason"], g["from_cycle"]) for g in s["gaps"]] == [("controller_restart", 1000)]
    assert 0 < s["wake_latency_ns"]["p50"] <= s["wake_latency_ns"]["p99"] <= \
        s["wake_latency_ns"]["max"] == s["max_latency_ns"]
    assert s["wake_latency_ns"]["max"] >= 60000  # the spike at cycle 1499
    txt = subprocess.run(servoamp_cmd("info", str(rec["path"])), capture_output=True, text=True,
                         timeout=60, env=ENV).stdout
    assert "cycles:      2000" in txt and "pos_kp = 62" in txt


def _png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and data[12:16] == b"IHDR", path
    w, h = struct.unpack(">II", data[16:24])
    return w, h


def test_plot_pngs(rec: dict[str, Any], tmp_path: Path) -> None:
    csv = tmp_path / "queues.csv"
    csv.write_text("t_us,stream_bytes,blocks,segments\n" +
                   "".join(f"{i * 1000},{i % 7},{i % 30},{(i * 3) % 50}\n" for i in range(200)))
    out = tmp_path / "plots"
    p = subprocess.run(servoamp_cmd("plot", str(rec["path"]), "-o", str(out), "--queues", str(csv)),
                       capture_output=True, text=True, timeout=120, env=ENV)
    assert p.returncode == 0, p.stderr
    names = {"xy_path.png", "following_error.png", "position.png", "latency_histogram.png",
             "queue_levels.png"}
    assert {Path(x).name for x in p.stdout.split()} == names
    for n in names:
        w, h = _png_size(out / n)
        assert 400 <= w <= 3000 and 300 <= h <= 3000, (n, w, h)
        assert (out / n).stat().st_size > 10_000, n
    # without --queues the recorded /servoamp/queues are used
    files = plot.plot(rec["path"], tmp_path / "p2")
    assert {f.name for f in files} == names


def _record_proc(port: int, out: Path, *extra: str) -> subprocess.Popen[str]:
    return subprocess.Popen(servoamp_cmd("record", "--connect", f"127.0.0.1:{port}", "-o",
                                         str(out), "--json", *extra),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV)


def _wait_cycles(out: Path, feed: Feed, rp: subprocess.Popen[str], n: int) -> None:
    """Until n cycles are on disk (flushed chunks), not a fixed sleep: a loaded
    host may need far longer to start the recorder. The limit only stops a hang."""
    end = time.monotonic() + 120
    while True:
        got = sum(1 for _ in mcapio.iter_messages(out, [mcapio.T_CYCLE])) if out.exists() else 0
        if got >= n:
            break
        assert rp.poll() is None, rp.communicate()
        assert time.monotonic() < end, f"{got} of {n} cycles on disk after 120 s"
        time.sleep(0.2)
    assert feed.proc.poll() is None


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_signal_leaves_finalized_file(feed_bin: Path, tmp_path: Path, sig: int,
                                      node_ready: None) -> None:
    out = tmp_path / "sig.mcap"
    feed = Feed(feed_bin, *_feed_args(20000, axes=4))
    try:
        rp = _record_proc(feed.port, out)
        _wait_cycles(out, feed, rp, 600)
        rp.send_signal(sig)
        so, se = rp.communicate(timeout=30)
    finally:
        feed.kill()
    assert rp.returncode == 0, se
    r = json.loads(so)
    assert r["stopped_by"] == "signal" and r["cycles"] > 500
    assert mcapio.has_footer(out)
    s = info.summarize(out)
    assert s["complete"] and s["read_error"] == "" and s["cycles"] == r["cycles"]
    js = node_verify(out)
    assert js["complete"] and js["cycles"]["count"] == r["cycles"]


def test_sigkill_leaves_readable_file(feed_bin: Path, tmp_path: Path, node_ready: None) -> None:
    out = tmp_path / "kill.mcap"
    feed = Feed(feed_bin, *_feed_args(20000, axes=8))
    try:
        rp = _record_proc(feed.port, out, "--flush-interval", "0.5")
        _wait_cycles(out, feed, rp, 1000)
        rp.kill()
        rp.communicate(timeout=30)
    finally:
        feed.kill()
    assert not mcapio.has_footer(out)
    s = info.summarize(out)
    # everything up to the last complete chunk: at most ~0.5 s (+ one chunk) lost
    assert not s["complete"] and s["cycles"] >= 1000, s
    cycles = [m["cycle"] for _t, _tt, m in mcapio.iter_json(out, [mcapio.T_CYCLE])]
    assert cycles == list(range(cycles[0], cycles[0] + len(cycles)))
    js = node_verify(out, stream=True)
    assert not js["complete"] and js["cycles"]["count"] == s["cycles"]


def test_producer_restart_is_a_marked_gap(feed_bin: Path, tmp_path: Path) -> None:
    out = tmp_path / "restart.mcap"
    port = free_port()
    result: dict[str, Any] = {}

    def run() -> None:
        result["r"] = record("127.0.0.1", port, out, duration=5.0, max_backoff=0.1)

    th = threading.Thread(target=run)
    th.start()
    a = Feed(feed_bin, *_feed_args(1200, axes=2), port=port)
    ra = a.result()
    time.sleep(0.3)  # the controller is away
    b = Feed(feed_bin, *_feed_args(800, axes=2, start_cycle="5000"), port=port)
    rb = b.result()
    th.join(timeout=30)
    res = result["r"]
    assert ra["sent"] == 1200 and rb["sent"] == 800
    assert res.cycles == 2000 and res.connections == 2
    gaps = [g for g in res.gaps if g["source"] == "recorder"]
    assert len(gaps) == 1
    g = gaps[0]
    assert g["reason"] == "producer_restart" and g["from_cycle"] == 1200 and g["to_cycle"] == 4999
    s = info.summarize(out)
    assert s["connections"] == 2 and s["cycles"] == 2000
    assert [x["reason"] for x in s["gaps"]] == ["producer_restart"]


def test_record_realtime_1khz_8_axes(feed_bin: Path, tmp_path: Path) -> None:
    """1 kHz, 8 axes, 3 s: nothing lost anywhere, and the CPU share it took."""
    out = tmp_path / "rt.mcap"
    feed = Feed(feed_bin, *_feed_args(3000, axes=8, rate=1000))
    try:
        res = record("127.0.0.1", feed.port, out, duration=60, reconnect=False)
        fres = feed.result()
    finally:
        feed.kill()
    share = res.cpu_s / res.wall_s
    print(f"1 kHz x 8 axes: {res.cycles} cycles, {res.messages} messages in {res.wall_s:.2f} s, "
          f"recorder CPU {res.cpu_s:.2f} s ({100 * share:.0f} % of one core), "
          f"{res.cycles / res.cpu_s:.0f} cycles per CPU second, file {out.stat().st_size} bytes")
    assert res.cycles == 3000 and fres["client_lost"] == 0 and fres["dropped"] == 0
    assert share < 0.6


def test_connect_refused_without_duration(tmp_path: Path) -> None:
    with pytest.raises(ConnectionError):
        record("127.0.0.1", free_port(), tmp_path / "x.mcap", connect_timeout=0.3)
    assert mcapio.has_footer(tmp_path / "x.mcap")  # still a valid (empty) file


def test_mypy_strict() -> None:
    mods = [str(TOP / "python" / "servoamp" / f"{m}.py")
            for m in ("telemetry", "mcapio", "record", "info", "plot", "cli", "netboard", "recovery_stress",
                      "demo_record", "bridge", "pbenc")]
    p = subprocess.run([str(Path(sys.executable).parent / "mypy"), "--strict", *mods],
                       capture_output=True, text=True, timeout=300, cwd=TOP)
    assert p.returncode == 0, p.stdout + p.stderr
