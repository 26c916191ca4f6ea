"""Who may connect to `servoamp bridge`'s live view, and who may set
parameters (issue 21, items 1 and 5; python/servoamp/wsfront.py), against
the real telem_feed with its stand-in parameter service on 127.0.0.1:

* a web page of a foreign origin is refused before the upgrade (HTTP 403),
  and a setParameters it would send changes nothing on the controller;
* a wrong token is refused the same way;
* a page of an allowed origin without the token sees the parameters,
  read-only: its set comes back as an error status, the value unchanged;
* the URL with the token sets (tests/recorder/test_bridge.py does that with
  the reference client);
* an older viewer offering only "foxglove.websocket.v1" is answered with that
  name and gets the stream;
* the SDK's own servers behind the front do not speak plain WebSocket: a
  page that finds their ports cannot connect.
"""

from __future__ import annotations

import json
import os
import socket
import ssl
import subprocess
import threading
import time
from pathlib import Path
from typing import Any, Iterator

import pytest

from recorder_helpers import TOP, Feed
from servoamp import bridge, wsfront, wsprobe

TOKEN = "access-test-token-0123"
WS_CHECK = TOP / "tools" / "mcap-verify" / "ws-check.mjs"


@pytest.fixture
def live(feed_bin: Path, node_ready: None) -> Iterator[bridge.Bridge]:
    """A bridge on a running feed (60 s at most), served in a thread."""
    feed = Feed(feed_bin, "--cycles", "60000", "--axes", "2", "--params", "--token", TOKEN,
                "--log-every", "500")
    b = bridge.Bridge("127.0.0.1", feed.port, token=TOKEN, ws_port=0, reconnect=False)
    stop = threading.Event()
    t = threading.Thread(target=b.run, kwargs={"duration": 120, "stop": stop}, daemon=True)
    t.start()
    deadline = time.monotonic() + 60  # a hang turned into a failure, not a timing test
    while b.hello is None and t.is_alive() and time.monotonic() < deadline:
        time.sleep(0.05)
    assert b.hello is not None, "the bridge did not connect to the feed"
    try:
        yield b
    finally:
        stop.set()
        t.join(timeout=30)
        b.close()
        feed.kill()


def _pos_kp(b: bridge.Bridge) -> str:
    return b.request("param get pos_kp").strip()


def _ws_check(url: str, *args: str) -> dict[str, Any]:
    p = subprocess.run(["node", str(WS_CHECK), url, "--timeout", "60", *args],
                       capture_output=True, text=True, timeout=120,
                       env=dict(os.environ, NODE_NO_WARNINGS="1"))
    out = json.loads(p.stdout)
    assert p.returncode == 0, (out, p.stderr)
    return dict(out)


@pytest.mark.parametrize("origin", ["https://evil.example", "http://localhost.evil.example:8080",
                                    "null"])
def test_foreign_origin_refused_before_upgrade(live: bridge.Bridge, origin: str) -> None:
    port = live.ws_port
    assert port is not None
    before = _pos_kp(live)
    status, head, s = wsprobe.upgrade(port, "/", origin)
    try:
        if status == 101:  # what the bridge did before the front: then the set goes through
            s.sendall(wsprobe.text_frame(json.dumps({"op": "setParameters", "id": "evil", "parameters": [
                {"name": "pos_kp", "value": 99.0, "type": "float64"}]}).encode()))
            s.settimeout(2)
            try:
                while s.recv(65536):
                    pass
            except OSError:
                pass
    finally:
        s.close()
    assert status == 403, head
    assert f"origin {origin} is not allowed" in head, head
    assert _pos_kp(live) == before


def test_wrong_token_refused(live: bridge.Bridge) -> None:
    port = live.ws_port
    assert port is not None
    for origin in (None, "http://127.0.0.1:3000"):
        status, head, s = wsprobe.upgrade(port, "/?token=not-the-token-0000000", origin)
        s.close()
        assert status == 403 and "wrong token" in head, head
    # the right one is let through, from any origin
    status, head, s = wsprobe.upgrade(port, f"/?token={live.ws_token}", "https://evil.example")
    s.close()
    assert status == 101, head


def test_allowed_origin_without_token_is_read_only(live: bridge.Bridge) -> None:
    before = _pos_kp(live)
    assert live.ws_url_plain is not None
    out = _ws_check(live.ws_url_plain, "--seconds", "0.5", "--param", "pos_kp", "--good", "71",
                    "--readonly", "--origin", "http://localhost:5173")
    names = {p["name"] for p in out["param_list"]}
    assert "pos_kp" in names  # the feed's stand-in service has just it
    ro = out["set_readonly"]
    assert "read-only" in ro["status"], ro
    assert ro["reply"] == ro["before"] and out["list_after"] == ro["before"], out
    assert not any(c["name"] == "pos_kp" for c in out["param_changes"]), out
    assert _pos_kp(live) == before


def test_older_viewer_subprotocol(live: bridge.Bridge) -> None:
    """Studio <= 1.87 and Lichtblick before December 2025 offer only the old name."""
    port = live.ws_port
    assert port is not None
    status, head, s = wsprobe.upgrade(port, "/", "http://localhost:8080", "foxglove.websocket.v1")
    s.close()
    assert status == 101, head
    assert "sec-websocket-protocol: foxglove.websocket.v1" in head.lower(), head
    # and the stream under it, by the reference client asking for the old name
    assert live.ws_url is not None
    out = _ws_check(live.ws_url, "--seconds", "0.5", "--subprotocol", "foxglove.websocket.v1")
    assert out["cycles"]["count"] > 0 and out["cycles"]["out_of_order"] == 0, out


def test_sdk_servers_behind_tls(live: bridge.Bridge) -> None:
    """A page that scans 127.0.0.1 for the SDK's own ports gets no WebSocket."""
    for srv in live.servers:
        status, head, s = wsprobe.upgrade(srv.port, "/", "https://evil.example")
        s.close()
        assert status != 101, head


def test_bad_requests_answered_400(live: bridge.Bridge) -> None:
    """A head over 16 KiB, or a request that is no WebSocket upgrade: 400,
    and the front goes on serving."""
    port = live.ws_port
    assert port is not None
    with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
        s.sendall(b"GET / HTTP/1.1\r\nX-Pad: " + b"a" * 20000 + b"\r\n\r\n")
        assert s.recv(4096).startswith(b"HTTP/1.1 400"), "oversize head"
    with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
        s.sendall(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n")
        assert s.recv(4096).startswith(b"HTTP/1.1 400"), "no upgrade"
    status, head, sk = wsprobe.upgrade(port, f"/?token={live.ws_token}", None)
    sk.close()
    assert status == 101, head


def _unverified_tls() -> ssl.SSLContext:
    """What any local process may use: TLS without verifying anything."""
    ctx = ssl.create_default_context()
    ctx.check_hostname = False
    ctx.verify_mode = ssl.CERT_NONE
    return ctx


def test_local_process_cannot_set_through_the_sdk_servers(live: bridge.Bridge) -> None:
    """Issue 36, item 11: a process of any uid finds the SDK servers' ports
    (/proc/net/tcp), speaks TLS to them without verifying, and sends
    setParameters. Before, the read-write server set pos_kp to 99; now only
    connections the front relayed with the token may set."""
    before = _pos_kp(live)
    for srv in live.servers:
        status, head, s = wsprobe.upgrade(srv.port, "/", None, tls=_unverified_tls())
        got = b""
        try:
            assert status == 101, head   # the SDK server itself: it authenticates nobody
            s.sendall(wsprobe.text_frame(json.dumps({"op": "setParameters", "id": "local", "parameters": [
                {"name": "pos_kp", "value": 99.0, "type": "float64"}]}).encode()))
            s.settimeout(0.5)
            deadline = time.monotonic() + 30   # a hang turned into a failure
            while b"parameterValues" not in got and time.monotonic() < deadline:
                try:
                    data = s.recv(65536)
                except (TimeoutError, ssl.SSLWantReadError):
                    continue
                if not data:
                    break
                got += data
        finally:
            s.close()
        assert b"parameterValues" in got, got[-400:]
        assert _pos_kp(live) == before, f"set through port {srv.port}"
        assert b"read-only" in got or b"did not come through" in got, got[-400:]
    # and the front's own path with the token still sets (the reference client)
    assert live.ws_url is not None
    out = _ws_check(live.ws_url, "--seconds", "0.5", "--param", "pos_kp", "--good", "72", "--bad", "-5")
    assert out["set_good"]["reply"] == 72, out


def test_request_head_has_one_deadline(live: bridge.Bridge) -> None:
    """Issue 36, item 12: 64 connections trickling a byte a second held
    every slot (the 5 s timeout was per recv()), and the operator's URL got
    503 for as long as they trickled. One deadline per head: they are
    answered 400 after 5 s and the token's URL gets through."""
    port = live.ws_port
    assert port is not None
    stop = threading.Event()
    answers: list[bytes] = []
    socks = [socket.create_connection(("127.0.0.1", port), timeout=10) for _ in range(wsfront.MAX_CONNS)]

    def trickle() -> None:
        while not stop.is_set():
            for s in socks:
                try:
                    s.sendall(b"G")
                except OSError:
                    pass
            stop.wait(1.0)

    th = threading.Thread(target=trickle, daemon=True)
    th.start()
    try:
        status, head = 0, ""
        deadline = time.monotonic() + 40   # tricklers keep trickling all along
        while status != 101 and time.monotonic() < deadline:
            status, head, s = wsprobe.upgrade(port, f"/?token={live.ws_token}", None)
            s.close()
            if status != 101:
                time.sleep(0.5)
        assert status == 101, head
        for s in socks:
            s.settimeout(10)
            try:
                answers.append(s.recv(4096))
            except OSError:
                answers.append(b"")
    finally:
        stop.set()
        th.join(timeout=5)
        for s in socks:
            s.close()
    assert all(a.startswith(b"HTTP/1.1 400") and b"within 5 s" in a for a in answers), answers[:3]


def test_malformed_target_answered_400(live: bridge.Bridge) -> None:
    """Issue 36, item 13: a target such as //[ raised ValueError in urlsplit
    before the Origin check: no answer, a traceback. Now 400."""
    port = live.ws_port
    assert port is not None
    for target in ("//[", "http://[::1/", "//[x]:1/"):
        with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
            s.sendall(f"GET {target} HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\n"
                      "Connection: Upgrade\r\n\r\n".encode())
            s.settimeout(10)
            try:
                got = s.recv(4096)
            except OSError:
                got = b""
            assert got.startswith(b"HTTP/1.1 400") and b"bad request target" in got, (target, got)
    status, head, sk = wsprobe.upgrade(port, f"/?token={live.ws_token}", None)
    sk.close()
    assert status == 101, head
