"""Who may connect to the telemetry server, and that no client can block the
others (issue 13, item 6): the real server (libtelem.a in telem_feed) on
127.0.0.1, with clients that never authenticate, sit idle, flood, or bring
the wrong token. Each case failed on the server before the AUTH frame and the
client deadlines (it streamed to anyone, kept idle connections forever,
refused the fifth connection, and read a flooding client in a loop)."""

from __future__ import annotations

import os
import socket
import threading
import time
from pathlib import Path

from recorder_helpers import Feed, make
from servoamp import telemetry as tw

TOKEN = "0123456789abcdef0123456789abcdef"


def _feed_bin() -> Path:
    """telem_feed of this tree; SERVOAMP_TELEM_FEED=PATH runs the cases
    against another build (e.g. the server before this change)."""
    other = os.environ.get("SERVOAMP_TELEM_FEED")
    return Path(other) if other else make("none") / "telem_feed"


def _connect(port: int) -> socket.socket:
    return socket.create_connection(("127.0.0.1", port), timeout=10)


def _until_eof(s: socket.socket, timeout: float) -> tuple[bool, bytes]:
    """(closed by the server within timeout, bytes received)."""
    got = b""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        s.settimeout(max(0.01, end - time.monotonic()))
        try:
            d = s.recv(65536)
        except socket.timeout:
            break
        except ConnectionResetError:
            return True, got
        if not d:
            return True, got
        got += d
    return False, got


def _hello(s: socket.socket, timeout: float = 5.0) -> tw.Hello | None:
    """The first frame, if it is a HELLO that arrives within timeout."""
    sp = tw.FrameSplitter()
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        s.settimeout(max(0.01, end - time.monotonic()))
        try:
            d = s.recv(4096)
        except (socket.timeout, ConnectionResetError):
            return None
        if not d:
            return None
        sp.feed(d)
        for typ, off, ln in sp.frames():
            return tw.decode_hello(bytes(sp.buf[off:off + ln])) if typ == tw.MSG_HELLO else None
    return None


def _count_cycles(s: socket.socket, timeout: float = 60.0) -> list[int]:
    """Cycle numbers received until EOF."""
    sp = tw.FrameSplitter()
    got: list[int] = []
    s.settimeout(timeout)
    while True:
        d = s.recv(1 << 16)
        if not d:
            return got
        sp.feed(d)
        for typ, off, _ln in sp.frames():
            if typ == tw.MSG_CYCLE:
                got.append(int.from_bytes(bytes(sp.buf[off:off + 8]), "little"))


def test_never_authenticating_client_is_dropped() -> None:
    """A connection that sends nothing gets nothing and is closed after the
    AUTH deadline (default 2 s), and its slot is free again."""
    feed = Feed(_feed_bin(), "--cycles", "6000", "--rate", "1000", "--axes", "2")
    try:
        with _connect(feed.port) as idle:
            t0 = time.monotonic()
            closed, got = _until_eof(idle, 5.0)
            waited = time.monotonic() - t0
        assert closed, f"a silent client kept its connection for 5 s ({len(got)} bytes streamed to it)"
        assert got == b"", "data sent before AUTH"
        assert 1.5 < waited < 4.0, waited
        with _connect(feed.port) as s:
            s.sendall(tw.encode_auth())
            assert _hello(s) is not None
        feed.proc.terminate()
        res = feed.result()
    finally:
        feed.kill()
    assert res["auth_timeout"] == 1 and res["clients_total"] == 2


def test_idle_connections_do_not_lock_out_the_recorder() -> None:
    """Five connections that never authenticate (more than the 4 slots) do
    not keep the recorder out: it gets its HELLO at once (the oldest
    unauthenticated connection gives up its slot) and every cycle."""
    feed = Feed(_feed_bin(), "--cycles", "3000", "--rate", "1000", "--axes", "2",
                "--wait-clients", "1")
    idle = [_connect(feed.port) for _ in range(5)]
    try:
        time.sleep(0.3)  # all five accepted
        with _connect(feed.port) as s:
            t0 = time.monotonic()
            s.sendall(tw.encode_auth())
            hello = _hello(s, timeout=5.0)
            assert hello is not None, "the recorder was locked out by idle connections"
            assert time.monotonic() - t0 < 1.0  # before any idle one timed out
            got = _count_cycles(s)
        res = feed.result()
    finally:
        for c in idle:
            c.close()
        feed.kill()
    assert got == list(range(3000))
    assert res["evicted"] == 2 and res["auth_timeout"] == 3, res


def test_stalled_clients_are_dropped() -> None:
    """Four authenticated clients that never read hold every slot until
    their sockets stay full for --stall-ms; then they are dropped (counted)
    and the recorder gets in."""
    feed = Feed(_feed_bin(), "--cycles", "200000", "--rate", "20000", "--axes", "8",
                "--client-buffer", "65536", "--stall-ms", "300")
    stalled = []
    try:
        for _ in range(4):
            c = socket.socket()
            c.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
            c.connect(("127.0.0.1", feed.port))
            c.sendall(tw.encode_auth())
            stalled.append(c)
        time.sleep(0.3)
        with _connect(feed.port) as s:  # all four slots stream to stalled clients
            s.sendall(tw.encode_auth())
            assert _hello(s, 2.0) is None
        end = time.monotonic() + 20
        hello = None
        while hello is None and time.monotonic() < end:
            with _connect(feed.port) as s:
                s.sendall(tw.encode_auth())
                hello = _hello(s, 2.0)
            if hello is None:
                time.sleep(0.2)
        assert hello is not None, "stalled clients kept every slot for 20 s"
        feed.proc.terminate()
        res = feed.result()
    finally:
        for c in stalled:
            c.close()
        feed.kill()
    assert res["stalled"] == 4 and res["refused"] >= 1, res


def test_flooding_clients_do_not_starve_the_drain() -> None:
    """Three authenticated clients that send as fast as they can: the drain
    thread reads a bounded amount from each per pass, drops them for
    sending more than AUTH, and the recorder gets every cycle from a 2048-record
    ring (2 s of headroom at 1 kHz: room for a loaded test machine, none for
    a drain thread kept in recv for the whole flood)."""
    feed = Feed(_feed_bin(), "--cycles", "5000", "--rate", "1000", "--axes", "2",
                "--ring", "2048", "--wait-clients", "1")
    stop = threading.Event()
    sent = [0, 0, 0]

    def flood(i: int) -> None:
        blob = b"\xa5" * (1 << 20)
        try:
            with _connect(feed.port) as f:
                f.sendall(tw.encode_auth())
                while not stop.is_set():
                    f.sendall(blob)
                    sent[i] += len(blob)
        except OSError:
            pass

    rec = _connect(feed.port)
    rec.sendall(tw.encode_auth())
    floods = [threading.Thread(target=flood, args=(i,), daemon=True) for i in range(3)]
    try:
        for th in floods:
            th.start()
        got = _count_cycles(rec)
        res = feed.result()
    finally:
        stop.set()
        rec.close()
        feed.kill()
        for th in floods:
            th.join(timeout=10)
    print(f"flooders sent {sent} bytes; {res}")
    assert res["dropped"] == 0, f"the drain thread fell behind: {res['dropped']} ring drops"
    assert got == list(range(5000))
    assert res["protocol"] == 3


def test_wrong_token_is_refused() -> None:
    """With a token: a wrong token, a token of another length, a malformed
    first frame and silence are all closed without a byte of telemetry; the
    right token gets the stream."""
    feed = Feed(_feed_bin(), "--cycles", "4000", "--rate", "1000", "--axes", "2",
                "--token", TOKEN, "--auth-ms", "500")
    try:
        bad = [tw.encode_auth(TOKEN[:-1] + "0"), tw.encode_auth(TOKEN[:-1]), tw.encode_auth(),
               tw.FRAME.pack(tw.MSG_HELLO, 0, 0), tw.FRAME.pack(tw.MSG_AUTH, 0, 1 << 20)]
        for b in bad:
            with _connect(feed.port) as s:
                s.sendall(b)
                closed, got = _until_eof(s, 3.0)
                assert closed and got == b"", (b, closed, len(got))
        with _connect(feed.port) as s:  # the token in two pieces is fine
            a = tw.encode_auth(TOKEN)
            s.sendall(a[:5])
            time.sleep(0.05)
            s.sendall(a[5:])
            hello = _hello(s)
            assert hello is not None and hello.controller_id == "telem_feed"
        feed.proc.terminate()
        res = feed.result()
    finally:
        feed.kill()
    assert res["auth_failed"] == len(bad) and res["auth_timeout"] == 0, res
