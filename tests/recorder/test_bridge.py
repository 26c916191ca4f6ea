"""servoamp bridge against the real telem_feed on 127.0.0.1 (the real
telemetry server, with its stand-in parameter service --params): the
Foxglove WebSocket side checked by the protocol's reference client
(tools/mcap-verify/ws-check.mjs, @foxglove/ws-protocol), the MCAP side by
the Python reader, `servoamp info`/`plot` and @mcap/core. The same on the
emulated board: tests/robot/test_bridge_board.py."""

from __future__ import annotations

import filecmp
import json
import re
import os
import shutil
import socket
import struct
import subprocess
import sys
import threading
from pathlib import Path
from typing import Any

import pytest

from recorder_helpers import TOP, Feed, node_verify, servoamp_cmd
from servoamp import bridge, info, mcapio, pbenc, plot
from servoamp import telemetry as tw
from servoamp.schemas import servoamp_pb2 as pb

TOKEN = "bridge-test-token-0123"
WS_CHECK = TOP / "tools" / "mcap-verify" / "ws-check.mjs"


def ws_check(url: str, *args: str, timeout: float = 120) -> subprocess.Popen[str]:
    return subprocess.Popen(["node", str(WS_CHECK), url, "--timeout", str(timeout), *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=dict(os.environ, NODE_NO_WARNINGS="1"))


@pytest.fixture(scope="module")
def run(feed_bin: Path, tmp_path_factory: pytest.TempPathFactory, node_ready: None
        ) -> dict[str, Any]:
    """6 s of 4 axes at 1 kHz through the bridge: the reference client
    subscribed for 2 s of controller time, then setting pos_kp to 70 (taken)
    and 5000 (refused); the same channels into MCAP."""
    out = tmp_path_factory.mktemp("bridge") / "run.mcap"
    feed = Feed(feed_bin, "--cycles", "6000", "--axes", "4", "--params", "--token", TOKEN,
                "--wait-clients", "1", "--log-every", "500", "--queues-every", "100")
    b = bridge.Bridge("127.0.0.1", feed.port, token=TOKEN, ws_port=0, mcap=out,
                      reconnect=False)
    try:
        assert b.ws_url is not None
        node = ws_check(b.ws_url, "--seconds", "2", "--param", "pos_kp", "--good", "70",
                        "--bad", "5000")
        res = b.run(duration=120)
        b.close()
        fres = feed.result()
        nout, nerr = node.communicate(timeout=120)
    finally:
        b.close()
        feed.kill()
    return {"path": out, "res": res, "feed": fres, "ws": json.loads(nout), "ws_err": nerr,
            "rc": node.returncode}


def test_reference_client_gets_every_cycle_in_order(run: dict[str, Any]) -> None:
    ws = run["ws"]
    assert run["rc"] == 0, (ws, run["ws_err"])
    c = ws["cycles"]
    print(f"ws client: {c['count']} cycles {c['first']}..{c['last']}")
    assert c["out_of_order"] == 0
    assert c["count"] == int(c["last"]) - int(c["first"]) + 1
    assert int(c["last_t"]) - int(c["first_t"]) >= 2_000_000_000
    assert ws["axes"] == 4
    topics = {ch["topic"]: (ch["encoding"], ch["schemaName"]) for ch in ws["channels"]}
    assert topics == {t: ("protobuf", f"servoamp.{m}") for t, m in bridge.CHANNELS.items()} | {
        bridge.T_LOG: ("protobuf", "foxglove.Log")}


def test_parameters_listed_set_and_refused(run: dict[str, Any]) -> None:
    ws = run["ws"]
    assert ws["param_list"] == [{"name": "pos_kp", "value": 50, "type": "float64"}]
    # the set went through the controller and came back on /servoamp/param
    assert ws["set_good"] == {"reply": 70, "channel": 70, "update": 70}
    assert {"name": "pos_kp", "value": 70} in ws["param_changes"]
    # the refusal: an error status with the controller's reason; nothing changed
    assert "out of range [0, 1000]" in ws["set_bad"]["status"]
    assert ws["set_bad"]["reply"] == 70 and ws["list_after"] == 70
    assert [p["value"] for p in ws["param_changes"]] == [70]


def test_mcap_has_every_cycle_and_reads_everywhere(run: dict[str, Any]) -> None:
    res, fres, path = run["res"], run["feed"], run["path"]
    assert fres["dropped"] == 0 and fres["client_lost"] == 0
    assert res.cycles == fres["sent"] == 6000 and res.gaps == []
    cycles = [m["cycle"] for _t, _tt, m in mcapio.iter_json(path, [mcapio.T_CYCLE])]
    assert cycles == list(range(6000))
    nv = node_verify(path)
    assert nv["complete"] and nv["decode_errors"] == 0 and nv["json_errors"] == 0
    assert nv["cycles"] == {"count": 6000, "first": 0, "last": 5999, "non_increasing": 0}
    assert nv["encodings"][bridge.T_CYCLE] == "protobuf"
    assert nv["schemas"][bridge.T_LOG] == "foxglove.Log"
    s = info.summarize(path)
    assert s["cycles"] == 6000 and s["n_axes"] == 4 and s["complete"]
    assert [(p["name"], p["value"]) for p in s["parameter_changes"]] == [("pos_kp", 70.0)]
    assert s["log_lines"] >= 10
    d = plot._load(path)
    assert len(d["cx"]) == 6000 and sorted(d["ferr"]) == [0, 1, 2, 3]
    assert len(d["ferr"][3]) == 6000


def test_info_and_plot_cli(run: dict[str, Any], tmp_path: Path) -> None:
    p = subprocess.run(servoamp_cmd("info", str(run["path"]), "--json"), capture_output=True,
                       text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout)["cycles"] == 6000
    p = subprocess.run(servoamp_cmd("plot", str(run["path"]), "-o", str(tmp_path)),
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    for f in ("xy_path.png", "following_error.png", "position.png", "latency_histogram.png"):
        assert (tmp_path / f).stat().st_size > 1000


def test_cycle_encoding_matches_the_schema() -> None:
    """The one-struct encoder writes what the protobuf runtime decodes, and
    the fast decoder reads what the runtime encodes (fields omitted too)."""
    for n in (1, 4, 8):
        ax: list[int] = []
        for i in range(n):
            ax += [1, -100000 * i - 7, 2000, -1, 0x27, 99999, -5, 3, -(2 ** 31)]
        vals = [2 ** 40 + 3, 1000, 5, 6, 150, 12000, 9, 4, 0x534E5552, -3, n] + ax
        raw = tw.cycle_struct(n).pack(*vals)
        data = pbenc.cycle_encoder(n, 10.0)(raw, 0)
        m = pb.Cycle.FromString(data)
        assert m.cycle == 2 ** 40 + 3 and m.irq_latency_ns == 1500.0 and m.result == -3
        assert m.exchange == pbenc.EXCHANGE_UNKNOWN  # 9 is no known code
        assert len(m.axes) == n and m.axes[-1].feedback.following_error == -(2 ** 31)
        assert m.axes[-1].command.target_pos == -100000 * (n - 1) - 7
        assert pbenc.decode_cycle(data) == pbenc.cycle_dict(pbenc.to_dict(m))
        m.axes[0].command.control_word = 0  # omitted by the runtime: the slow path
        assert pbenc.decode_cycle(m.SerializeToString())["axes"][0]["command"]["control_word"] \
            == 0


def test_generated_protobuf_module_is_current(tmp_path: Path) -> None:
    """schemas/servoamp_pb2.py(i) are what tools/foxglove/gen_proto.sh makes of servoamp.proto."""
    pytest.importorskip("grpc_tools")
    src = TOP / "python" / "servoamp" / "schemas"
    shutil.copy(src / "servoamp.proto", tmp_path)
    subprocess.run([sys.executable, "-m", "grpc_tools.protoc", "-I.", "--python_out=.",
                    "--pyi_out=.", "servoamp.proto"], cwd=tmp_path, check=True)
    for f in ("servoamp_pb2.py", "servoamp_pb2.pyi"):
        assert filecmp.cmp(src / f, tmp_path / f, shallow=False), f"{f}: run tools/foxglove/gen_proto.sh"


# ---- the REQUEST frame on the telemetry server (linux/telemetry) ----------------------

def _session(port: int, token: str) -> tuple[socket.socket, tw.FrameSplitter]:
    s = socket.create_connection(("127.0.0.1", port), timeout=10)
    s.sendall(tw.encode_auth(token))
    return s, tw.FrameSplitter()


def _reply(s: socket.socket, sp: tw.FrameSplitter, timeout: float = 30) -> tuple[int, int, str]:
    s.settimeout(timeout)
    while True:
        data = s.recv(1 << 16)
        if not data:
            raise EOFError("closed")
        sp.feed(data)
        for typ, off, ln in sp.frames():
            if typ == bridge.MSG_REPLY:
                rid, st, n = bridge.REPLY_HDR.unpack_from(sp.buf, off)
                return rid, st, bytes(sp.buf[off + 12:off + 12 + n]).decode()


def _request(rid: int, text: str) -> bytes:
    b = text.encode()
    return tw.FRAME.pack(bridge.MSG_REQUEST, 0, 4 + len(b)) + struct.pack("<I", rid) + b


def test_requests_refused_where_not_served(feed_bin: Path) -> None:
    """A server that takes no requests (servod without a token) answers
    'unserved' and stays connected."""
    feed = Feed(feed_bin, "--cycles", "3000", "--axes", "1", "--wait-clients", "1")
    try:
        s, sp = _session(feed.port, "")
        s.sendall(_request(7, "param set pos_kp 70"))
        assert _reply(s, sp)[:2] == (7, -2)
        s.close()
    finally:
        feed.kill()


def test_non_request_frames_close_the_client(feed_bin: Path) -> None:
    """After AUTH only REQUEST frames are taken; an oversized one, or any
    other type, closes the connection (counted as `protocol`)."""
    feed = Feed(feed_bin, "--cycles", "3000", "--axes", "1",
                "--params", "--token", TOKEN)
    try:
        a, _ = _session(feed.port, TOKEN)
        b, _ = _session(feed.port, TOKEN)
        a.sendall(tw.FRAME.pack(bridge.MSG_REQUEST, 0, 4 + 257) + b"\0" * 261)
        b.sendall(tw.FRAME.pack(tw.MSG_AUTH, 0, 0))
        for s in (a, b):
            s.settimeout(30)
            try:
                while s.recv(1 << 16):
                    pass
            except ConnectionResetError:
                pass  # closed with unread bytes: a reset
        res = feed.result()
    finally:
        feed.kill()
    assert res["protocol"] == 2


_SEG = re.compile(r"""\.?(?P<name>@?[A-Za-z_][A-Za-z0-9_]*)
                     (?P<idx>\[(?:-?\d+|:|-?\d*:-?\d*)\])?
                     (?P<filt>\{(?P<ff>[A-Za-z_][A-Za-z0-9_]*)==(?P<fv>"[^"]*"|-?[\d.]+)\})?""",
                  re.X)
MODIFIERS = {"@derivative", "@abs", "@negative", "@sqrt", "@degrees", "@radians"}


def resolve_path(msg: Any, path: str, whole: bool = False) -> str | None:
    """A Foxglove message path below the topic (``.a[0].b``, ``[:]``,
    ``{key=="x"}``, a final ``.@derivative``) against a protobuf descriptor,
    the way the viewer reads the message: a map field is a list of
    {key, value} entries, which takes an index or a filter. A plotted path
    ends on a number; ``whole`` (a table, a raw view) may end on a list or a
    message. None if it resolves, else why not."""
    d, pos, leaf = msg, 0, False
    path = "." + path if path and not path.startswith(".") else path
    while pos < len(path):
        m = _SEG.match(path, pos)
        if m is None or m.end() == pos:
            return f"cannot parse {path[pos:]!r}"
        pos = m.end()
        name = m.group("name")
        if name.startswith("@"):
            if name not in MODIFIERS or pos != len(path) or not leaf:
                return f"{name}: a modifier, last and on a number"
            return None
        if d is None:
            return f"{name}: below a scalar"
        f = d.fields_by_name.get(name)
        if f is None:
            return f"no field {name!r} in {d.full_name}"
        repeated = f.is_repeated  # a map too: repeated entries
        last = pos == len(path)
        if repeated and not (m.group("idx") or m.group("filt")) and not (whole and last):
            return f"{name} is a list (a map: a list of {{key, value}}): index or filter it"
        if not repeated and (m.group("idx") or m.group("filt")):
            return f"{name} is not a list"
        if m.group("filt"):
            et = f.message_type
            if et is None or m.group("ff") not in et.fields_by_name:
                return f"filter on {m.group('ff')!r}: not a field of {name}'s elements"
        d = f.message_type
        leaf = d is None
    if not whole and not leaf:
        return "a plotted path must end on a number"
    return None


def _queue_names() -> set[str]:
    src = (TOP / "motion" / "src" / "pipeline.c").read_text()
    arr = re.search(r"queue_names\[[^]]*\] = \{(.*?)\};", src, re.S)
    assert arr, "queue_names not found in motion/src/pipeline.c"
    return set(re.findall(r'"([a-z_]+)"', arr.group(1)))


def test_path_resolver_refuses_what_the_viewer_cannot_plot() -> None:
    """The check below is not vacuous: the paths the issue found plotting
    nothing are refused, their working forms accepted."""
    q = pb.DESCRIPTOR.message_types_by_name["QueueLevels"]
    s = pb.DESCRIPTOR.message_types_by_name["Stats"]
    c = pb.DESCRIPTOR.message_types_by_name["Cycle"]
    assert resolve_path(q, "levels.blocks") is not None
    assert resolve_path(q, "levels[:]{key==\"blocks\"}.value") is None
    assert resolve_path(s, "counters.cycles") is not None
    assert resolve_path(s, "counters") is not None
    assert resolve_path(s, "counters", whole=True) is None
    assert resolve_path(s, "last_cycle") is None
    assert resolve_path(s, "counters[:]{key==\"cycles\"}.value") is None
    assert resolve_path(c, "axes[0].feedback.actual_pos") is None
    assert resolve_path(c, "axes.feedback.actual_pos") is not None
    assert resolve_path(c, "axes[0].feedback.nonesuch") is not None
    assert resolve_path(c, "cycle.@derivative") is None
    assert resolve_path(c, "axes[0].@derivative") is not None


def test_layout_matches_generator_and_the_bridge_channels(tmp_path: Path) -> None:
    """tools/foxglove/servoamp-layout.json is make_layout.py's output, and
    every path in it is a channel the bridge serves with a field its schema has."""
    layout = TOP / "tools" / "foxglove" / "servoamp-layout.json"
    gen = tmp_path / "layout.json"
    subprocess.run([sys.executable, str(TOP / "tools" / "foxglove" / "make_layout.py"), "-o",
                    str(gen)], check=True)
    assert json.loads(layout.read_text()) == json.loads(gen.read_text())
    refs: list[tuple[str, bool]] = []  # (path, whole)
    for cfg in json.loads(layout.read_text())["configById"].values():
        refs += [(p["value"], False) for p in cfg.get("paths", [])]
        if "xAxisPath" in cfg:
            refs.append((cfg["xAxisPath"]["value"], False))
        refs += [(cfg[k], True) for k in ("topicToRender", "topicPath") if k in cfg]
    assert refs
    queues = _queue_names()
    bad = []
    for r, whole in refs:
        topic, dot, path = r.partition(".")
        if topic not in bridge.TOPICS:
            bad.append(f"{r}: no channel {topic}")
            continue
        if path and topic in bridge.CHANNELS:
            desc = pb.DESCRIPTOR.message_types_by_name[bridge.CHANNELS[topic]]
            why = resolve_path(desc, path, whole)
            if why:
                bad.append(f"{r}: {why}")
        for key in re.findall(r'\{key=="([^"]*)"\}', r):
            if topic == bridge.T_QUEUES and key not in queues:
                bad.append(f"{r}: no queue {key!r} in the motion pipeline ({sorted(queues)})")
    assert not bad, "\n".join(bad)


def test_websocket_server_on_loopback_only(tmp_path: Path) -> None:
    """Whoever reaches the WebSocket port acts with the bridge's token: an
    address other than loopback is refused before anything is opened."""
    for host in ("0.0.0.0", "10.0.2.2", "::"):
        with pytest.raises(ValueError, match="not a loopback address"):
            bridge.Bridge("127.0.0.1", 1, ws_host=host, ws_port=0, mcap=tmp_path / "x.mcap")
    assert not (tmp_path / "x.mcap").exists()
    assert all(bridge.is_loopback(h) for h in ("127.0.0.1", "127.1.2.3", "::1", "localhost"))
    p = subprocess.run(servoamp_cmd("bridge", "--connect", "127.0.0.1:1", "--listen",
                                    "0.0.0.0:0", "--duration", "1"),
                       capture_output=True, text=True, timeout=60)
    assert p.returncode == 4 and "not a loopback address" in p.stderr


def test_cli_sigint_leaves_a_finalized_file(feed_bin: Path, tmp_path: Path) -> None:
    """`servoamp bridge` stopped with SIGINT: the MCAP file is finished
    (summary, footer) and has the cycles bridged so far."""
    import signal
    import time

    out = tmp_path / "run.mcap"
    feed = Feed(feed_bin, "--cycles", "60000", "--axes", "2", "--wait-clients", "1")
    proc = subprocess.Popen(servoamp_cmd("bridge", "--connect", f"127.0.0.1:{feed.port}",
                                         "--listen", "127.0.0.1:0", "--mcap", str(out),
                                         "--json"),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        first = proc.stdout.readline()
        assert first.startswith("servoamp bridge: Foxglove WebSocket on ws://127.0.0.1:"), first
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and (not out.exists() or out.stat().st_size < 20000):
            time.sleep(0.2)
        proc.send_signal(signal.SIGINT)
        rest, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
        feed.kill()
    assert proc.returncode == 0, err
    res = json.loads(rest.strip().splitlines()[-1])
    assert res["stopped_by"] == "signal" and res["cycles"] > 0
    s = info.summarize(out)
    assert s["complete"] and s["cycles"] == res["cycles"]


def test_guest_clock_offset_from_cycle_records_and_stamps() -> None:
    """bridge.GuestClock: the emulator's virtual time on the cycle records'
    clock. gt - monotonic from (t_ns, wake-up latency, t_cycle) of fresh
    records (median of SAMPLES, 32-bit t_cycle unwrapped), virtual - gt
    from the master's time stamp (32-bit us) at its start on the bus.
    The Zynq-7000: the A9 global timer at 100 MHz, Linux's clocksource
    (a few ms apart); the ZynqMP: the R5's cycle counter at 1 GHz, started
    with the firmware 37 s after Linux's clock, wrapping every 4.3 s (gt -
    monotonic known modulo a wrap). Virtual - monotonic is under a wrap
    (Linux's timekeeping starts 0.45 s into the emulator's clock)."""
    virt_mono = 450_000_000
    for hz, gt_mono in ((100_000_000, 6_512_000), (1_000_000_000, -37_000_000_000)):
        virt_gt = virt_mono - gt_mono
        wrap_ns = (1 << 32) * 1_000_000_000 // hz
        wrap_s = wrap_ns / 1e9              # 42.9 s, 4.3 s
        for start_s in (38.0, 37 + wrap_s - 0.01, 37 + 3 * wrap_s + 7.0):   # before, at and after wraps
            c = bridge.GuestClock()
            known = []
            for k in range(bridge.GuestClock.SAMPLES):
                event = int((start_s + k * 1e-3) * 1e9)          # the cycle interrupt, monotonic
                lat = 20_000 + 1_000 * (k % 7)
                ticks = ((event + gt_mono) * hz // 1_000_000_000 + 3) % (1 << 32)   # servo: 3 ticks late
                if k == 5:
                    ticks = (ticks - hz // 1000) % (1 << 32)       # a record of the cycle before
                known.append(c.add_cycle(event + lat, lat, ticks, hz))
            assert not any(known) and c.offset_ns is None       # no stamp yet
            assert c.gt_minus_mono_ns is not None
            assert abs((c.gt_minus_mono_ns - gt_mono + wrap_ns // 2) % wrap_ns - wrap_ns // 2) <= 40
            gt_us = (int(start_s * 1e9) + gt_mono) // 1000 + 1234   # a stamp: the timer in us, 32 bits
            assert c.add_stamp(virt_gt + gt_us * 1000, gt_us % (1 << 32))
            off = virt_mono
            assert c.offset_ns is not None and abs(c.offset_ns - off) <= 40, (hz, start_s, c.offset_ns)
            assert abs(c.to_monotonic(off + 2_000_000_000) - 2_000_000_000) <= 40
            # known once and for all: later records and stamps do not move it
            assert not c.add_cycle(10**12, 0, 0, hz) and not c.add_stamp(0, 5)
            assert abs(c.offset_ns - off) <= 40
    hz = 100_000_000
    virt_gt = virt_mono
    # the stamp first, then the records
    c = bridge.GuestClock()
    assert not c.add_stamp(virt_gt + 7_000_000, 7_000)
    assert [c.add_cycle(10**9 + 10**6 * k, 0, (10**9 + 10**6 * k) // 10, hz)
            for k in range(bridge.GuestClock.SAMPLES)][-1] is True
    assert c.offset_ns == virt_gt
    # no clock rate in the HELLO: never known (frames wait, counted as lost at the end)
    c = bridge.GuestClock()
    assert not any(c.add_cycle(10**9, 0, 1000, 0) for _ in range(50)) and c.offset_ns is None
    # a machine without servod (servoamp bridge --no-telemetry): the emulator's
    # virtual time itself, known at once (the frames are logged, not held)
    assert bridge.GuestClock.virtual().offset_ns == 0
