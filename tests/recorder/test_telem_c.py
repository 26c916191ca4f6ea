"""The telemetry transport in C: unit tests under the plain build,
ASan+UBSan and TSan; the stand-in producer under the sanitizers with a real
TCP client; the target (armhf) build."""

from __future__ import annotations

import shutil
import socket
import subprocess
import time

import pytest

from recorder_helpers import Feed, make
from servoamp import telemetry as tw

N = {"none": 2_000_000, "asan": 500_000, "tsan": 200_000}


@pytest.mark.parametrize("san", ["none", "asan", "tsan"])
def test_transport_unit(san: str) -> None:
    build = make(san)
    p = subprocess.run([str(build / "test_telem_transport"), str(N[san])], capture_output=True,
                       text=True, timeout=300)
    out = p.stdout + p.stderr
    print(out)
    assert p.returncode == 0, out
    assert "2 passed, 0 failed" in out
    assert "Sanitizer" not in out and "runtime error" not in out


def _read_stream(port: int, timeout: float = 30, stall: float = 0.0,
                 token: str | None = None) -> list[tuple[int, object]]:
    """A minimal client: AUTH, then decodes every frame until EOF (after the
    final STATS); stall: seconds it does not read after connecting (a slow
    client)."""
    msgs: list[tuple[int, object]] = []
    sp = tw.FrameSplitter()
    hello = None
    with socket.create_connection(("127.0.0.1", port), timeout=timeout) as s:
        s.sendall(tw.encode_auth(token))
        if stall:
            time.sleep(stall)
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            data = s.recv(1 << 16)
            if not data:
                break
            sp.feed(data)
            for typ, off, ln in sp.frames():
                payload = bytes(sp.buf[off:off + ln])
                if typ == tw.MSG_HELLO:
                    hello = tw.decode_hello(payload)
                    msgs.append((typ, hello))
                elif typ == tw.MSG_CYCLE:
                    assert hello is not None
                    msgs.append((typ, tw.cycle_struct(hello.n_axes).unpack(payload)))
                elif typ == tw.MSG_STATS:
                    msgs.append((typ, tw.decode_stats(payload)))
                elif typ == tw.MSG_GAP:
                    msgs.append((typ, tw.decode_gap(payload)))
                elif typ == tw.MSG_LOG:
                    msgs.append((typ, tw.decode_log(payload)))
                elif typ == tw.MSG_PARAM:
                    msgs.append((typ, tw.decode_param(payload)))
                elif typ == tw.MSG_QUEUES:
                    msgs.append((typ, tw.decode_queues(payload)))
                else:
                    raise AssertionError(f"unknown frame type {typ}")
    return msgs


@pytest.mark.parametrize("san,stall", [("none", 0.0), ("asan", 0.0), ("tsan", 0.0),
                                       ("none", 1.0)])
def test_feed_stream_and_exact_drop_accounting(san: str, stall: float) -> None:
    """telem_feed (real ring + server) in burst mode with a tiny ring: every
    pushed cycle is either received, or inside a ring-overflow GAP whose
    counts add up to the producer's drop counter."""
    build = make(san)
    cycles = {"none": 60000, "asan": 20000, "tsan": 8000}[san]
    ring = "64" if not stall else "131072"  # slow client: the loss is at the client buffer
    feed = Feed(build / "telem_feed", "--cycles", str(cycles), "--axes", "3", "--ring", ring,
                "--client-buffer", "65536",
                "--burst", "--wait-clients", "1", "--param-every", "1000", "--log-every", "999",
                "--queues-every", "500", "--restart-at", "5000")
    try:
        msgs = _read_stream(feed.port, stall=stall)
        res = feed.result()
    finally:
        feed.kill()
    assert msgs[0][0] == tw.MSG_HELLO
    hello = msgs[0][1]
    assert isinstance(hello, tw.Hello) and hello.n_axes == 3 and hello.version == 1
    got = [m[1][0] for m in msgs if m[0] == tw.MSG_CYCLE]  # type: ignore[index]
    gaps = [m[1] for m in msgs if m[0] == tw.MSG_GAP]
    ring = [g for g in gaps if isinstance(g, tw.Gap) and g.reason == "ring_overflow"]
    client = [g for g in gaps if isinstance(g, tw.Gap) and g.reason == "client_overflow"]
    restart = [g for g in gaps if isinstance(g, tw.Gap) and g.reason == "controller_restart"]
    stats = [m[1] for m in msgs if m[0] == tw.MSG_STATS]
    final = stats[-1]
    assert isinstance(final, tw.Stats) and final.final
    print(f"{san}: received {len(got)}, ring drops {res['dropped']} in {len(ring)} gaps, "
          f"client lost {res['client_lost']}, hw {res['ring_high_water']}")
    assert got == sorted(got) and len(set(got)) == len(got)  # order kept, no duplicates
    assert res["pushed"] == cycles and final.pushed == cycles
    assert res["dropped"] == final.dropped
    # a client too slow to take a ring gap gets it folded into its own overflow gap
    assert sum(g.count for g in ring) + sum(g.count for g in client) == \
        res["dropped"] + res["client_lost"]
    if not client:
        assert sum(g.count for g in ring) == res["dropped"]
    assert len(got) + res["dropped"] + res["client_lost"] == cycles
    # every hole in the received sequence is covered by a gap of the right size
    covered = set(got)
    for g in ring + client:
        assert g.to_cycle - g.from_cycle + 1 == g.count
        covered.update(range(g.from_cycle, g.to_cycle + 1))
    assert covered == set(range(cycles))
    if stall:
        assert res["client_lost"] > 0 and client
    if 5000 < cycles and final.client_events_lost == 0:
        assert len(restart) == 1 and restart[0].from_cycle == 5000


def test_feed_paced_no_loss() -> None:
    """At a real cycle rate nothing is lost and the counters agree."""
    build = make("none")
    feed = Feed(build / "telem_feed", "--cycles", "500", "--rate", "2000", "--axes", "8",
                "--wait-clients", "1")
    try:
        msgs = _read_stream(feed.port)
        res = feed.result()
    finally:
        feed.kill()
    got = [m[1][0] for m in msgs if m[0] == tw.MSG_CYCLE]  # type: ignore[index]
    assert got == list(range(500))
    assert res["dropped"] == 0 and res["client_lost"] == 0
    # values: following error = target - actual on every axis
    for typ, v in msgs:
        if typ == tw.MSG_CYCLE:
            assert isinstance(v, tuple)
            for i in range(8):
                a = 11 + 9 * i
                assert v[a + 8] == v[a + 1] - v[a + 5]


def test_bad_listen_address_and_port_in_use() -> None:
    build = make("none")
    p = subprocess.run([str(build / "telem_feed"), "--addr", "not-an-address", "--port", "0"],
                       capture_output=True, text=True, timeout=10)
    assert p.returncode == 1 and "telem_init" in p.stderr
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen(1)
        port = s.getsockname()[1]
        p = subprocess.run([str(build / "telem_feed"), "--port", str(port)],
                           capture_output=True, text=True, timeout=10)
        assert p.returncode == 1 and "telem_init" in p.stderr


def test_ipv6_loopback() -> None:
    if not socket.has_ipv6:
        pytest.skip("no IPv6")
    build = make("none")
    proc = subprocess.Popen([str(build / "telem_feed"), "--addr", "::1", "--port", "0",
                             "--cycles", "50", "--wait-clients", "1", "--rate", "5000"],
                            stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    line = proc.stdout.readline()
    if not line.startswith("listening"):
        proc.wait()
        pytest.skip("no IPv6 loopback here")
    port = int(line.split()[2])
    with socket.create_connection(("::1", port), timeout=10) as s:
        s.sendall(tw.encode_auth())
        data = b""
        while True:
            d = s.recv(65536)
            if not d:
                break
            data += d
    proc.wait(timeout=10)
    typ, _f, ln = tw.FRAME.unpack_from(data)
    assert typ == tw.MSG_HELLO and tw.decode_hello(data[8:8 + ln]).n_axes == 4


def test_target_build_armhf() -> None:
    if shutil.which("arm-linux-gnueabihf-gcc") is None:
        pytest.skip("arm-linux-gnueabihf-gcc not installed")
    make("none", "cross")


@pytest.mark.parametrize("snapshot", [True, False])
def test_stats_counters_and_totals_are_one_snapshot(snapshot: bool) -> None:
    """An application that pushes a cycle and then counts it (servod:
    telemetry_cycle, then cycle_stats_end) publishes a seqcount around both
    (telem_cfg.app_seq): every STATS then has the application's cycle count
    equal to its pushed total, however the drain thread's reads fall. The
    feed holds each cycle 300 us between its push and its count (a third of
    its period): without the seqcount (--no-snapshot) STATS taken in that
    window disagree, as the recording test on the board once saw
    (servod.cycles 6959, pushed 6960)."""
    feed = Feed(make("none") / "telem_feed", "--cycles", "1500", "--rate", "1000",
                "--stats-ms", "5", "--publish-delay-us", "300",
                *([] if snapshot else ["--no-snapshot"]))
    try:
        msgs = _read_stream(feed.port, timeout=60)
        res = feed.result()
    finally:
        feed.kill()
    stats = [m for typ, m in msgs if typ == tw.MSG_STATS]
    assert isinstance(stats[-1], tw.Stats) and stats[-1].final
    assert stats[-1].counters["cycles"] == stats[-1].pushed == res["pushed"] == 1500
    pairs = [(s.counters["cycles"], s.pushed) for s in stats if isinstance(s, tw.Stats)]
    assert len(pairs) > 100, len(pairs)
    off = [(c, p) for c, p in pairs if c != p]
    if snapshot:
        assert off == [], off[:10]
    else:
        # the window is a sleep, a third of each period: STATS land in it
        # whatever the host's load (at 5 ms apart, one in three or so)
        assert off and all(c == p - 1 for c, p in off), off[:10]
