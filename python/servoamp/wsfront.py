"""The bridge's WebSocket front: who may connect, and who may set parameters.

The Foxglove SDK's WebSocket server has no access control of its own: any
web page open in the operator's browser could connect to it and set the
controller's parameters (browsers let pages open WebSockets to 127.0.0.1).
So the SDK's servers are never reachable by a browser; this front listens
on the bridge's port instead and, for every connection:

1. reads the HTTP upgrade request (at most 16 KiB, 5 s) and decides:

   - the URL's ``token`` query parameter equals the bridge's token: the
     client may set parameters, whatever its Origin (the URL the bridge
     prints carries it; a web page cannot know it);
   - no token, and either no Origin header (not a browser: a script, which
     could as well use ampctl) or an Origin on the allow-list (by default
     the Foxglove app and pages served from this machine, any port): the
     client sees everything, parameters read-only (a set is refused with an
     error status, nothing changes);
   - a wrong token, or a foreign Origin: refused before the upgrade (HTTP
     403, the reason in the body), and said once per origin on stderr;

2. passes the request to one of two SDK servers (read-write, read-only),
   reached over TLS with a certificate made for this bridge and pinned: a
   browser cannot complete that handshake, so a page that finds their ports
   gets nowhere;

3. renames the subprotocol for older viewers: foxglove-sdk 0.30 speaks only
   ``foxglove.sdk.v1`` (the protocol of ``foxglove.websocket.v1``, renamed),
   which Foxglove Studio up to 1.87 and Lichtblick before December 2025 do
   not offer; a client that offers only the old name gets it back in the
   answer and the same protocol underneath;

4. relays the bytes both ways until either side closes. It buffers nothing
   beyond one read: a viewer that stops reading holds the relay back, and
   the SDK server's own per-client backlog (bounded) drops what does not fit.

docs/recording.md, "Live: who may connect".
"""

from __future__ import annotations

import hmac
import json
import os
import selectors
import shutil
import socket
import ssl
import subprocess
import sys
import tempfile
import struct
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable
from urllib.parse import parse_qsl, urlencode, urlsplit, urlunsplit

SUBPROTOCOL = "foxglove.sdk.v1"
SUBPROTOCOL_OLD = "foxglove.websocket.v1"
HEAD_MAX = 16384
HEAD_TIMEOUT_S = 5.0
# a viewer that reads nothing for this long is dropped (its relay would
# otherwise hold a thread and the SDK's backlog for it forever)
STALL_TIMEOUT_S = 30.0
# connections at once (handshakes and relays): more are answered 503 at once
MAX_CONNS = 64

# ":*" at the end: any port (or none)
DEFAULT_ORIGINS = ("https://app.foxglove.dev", "http://localhost:*", "http://127.0.0.1:*",
                   "http://[::1]:*")


def origin_allowed(origin: str, allowed: tuple[str, ...] | list[str]) -> bool:
    """Origin (scheme://host[:port], as browsers send it) against the list."""
    o = origin.strip().lower().rstrip("/")
    for a in allowed:
        a = a.strip().lower().rstrip("/")
        if a.endswith(":*"):
            base = a[:-2]
            if o == base:
                return True
            if o.startswith(base + ":") and o[len(base) + 1:].isdigit():
                return True
        elif o == a:
            return True
    return False


@dataclass
class Head:
    method: str
    target: str
    version: str
    headers: list[tuple[str, str]]

    def get(self, name: str) -> str | None:
        vals = [v for k, v in self.headers if k.lower() == name]
        return ", ".join(vals) if vals else None

    def replace(self, name: str, value: str) -> None:
        self.headers = [(k, v) for k, v in self.headers if k.lower() != name] + [(name, value)]

    def encode(self) -> bytes:
        lines = [f"{self.method} {self.target} {self.version}"]
        lines += [f"{k}: {v}" for k, v in self.headers]
        return ("\r\n".join(lines) + "\r\n\r\n").encode("latin-1")


class HeadError(Exception):
    pass


def read_head(sock: socket.socket, limit: int = HEAD_MAX,
              timeout: float | None = None) -> tuple[bytes, bytes]:
    """An HTTP head (up to the blank line) and what came after it. With a
    timeout, the whole head must come within it (one deadline, however the
    bytes trickle in); without, each read has the socket's own timeout."""
    buf = b""
    deadline = None if timeout is None else time.monotonic() + timeout
    while b"\r\n\r\n" not in buf:
        if len(buf) > limit:
            raise HeadError(f"request head over {limit} bytes")
        if deadline is not None:
            left = deadline - time.monotonic()
            if left <= 0:
                raise HeadError(f"no complete request head within {timeout:g} s")
            sock.settimeout(left)
        try:
            data = sock.recv(4096)
        except socket.timeout:
            if deadline is not None:
                raise HeadError(f"no complete request head within {timeout:g} s") from None
            raise HeadError("no complete request head: timed out") from None
        except (ssl.SSLError, OSError) as e:
            raise HeadError(f"no complete request head: {e}") from None
        if not data:
            raise HeadError("closed before the request head ended")
        buf += data
    head, _, rest = buf.partition(b"\r\n\r\n")
    if len(head) > limit:
        raise HeadError(f"request head over {limit} bytes")
    return head, rest


def parse_head(raw: bytes) -> Head:
    lines = raw.decode("latin-1").split("\r\n")  # latin-1 decodes every byte
    parts = lines[0].split(" ")
    if len(parts) != 3:
        raise HeadError(f"bad start line {lines[0][:80]!r}")
    hdrs: list[tuple[str, str]] = []
    for ln in lines[1:]:
        if ":" not in ln:
            raise HeadError(f"bad header line {ln[:80]!r}")
        k, v = ln.split(":", 1)
        hdrs.append((k.strip(), v.strip()))
    return Head(parts[0], parts[1], parts[2], hdrs)


def _answer(sock: socket.socket, code: int, reason: str, text: str) -> None:
    body = (text + "\n").encode()
    try:
        sock.sendall(f"HTTP/1.1 {code} {reason}\r\nContent-Type: text/plain; charset=utf-8\r\n"
                     f"Content-Length: {len(body)}\r\nConnection: close\r\n\r\n".encode() + body)
    except OSError:
        pass


def make_tls(dirpath: Path) -> tuple[bytes, bytes, ssl.SSLContext]:
    """A self-signed certificate for 127.0.0.1 (the SDK servers' identity)
    and a client context that trusts only it."""
    openssl = shutil.which("openssl")
    if openssl is None:
        raise RuntimeError("openssl not found: the bridge makes its internal TLS certificate "
                           "with it (scripts/bootstrap.sh installs it)")
    key, crt = dirpath / "key.pem", dirpath / "cert.pem"
    r = subprocess.run([openssl, "req", "-x509", "-newkey", "ec", "-pkeyopt",
                        "ec_paramgen_curve:prime256v1", "-nodes", "-keyout", str(key),
                        "-out", str(crt), "-days", "30", "-subj", "/CN=servoamp-bridge",
                        "-addext", "subjectAltName=IP:127.0.0.1"],
                       capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"openssl could not make the internal certificate: {r.stderr.strip()}")
    ctx = ssl.create_default_context(ssl.Purpose.SERVER_AUTH, cafile=str(crt))
    ctx.check_hostname = True
    return crt.read_bytes(), key.read_bytes(), ctx


def new_tls() -> tuple[bytes, bytes, ssl.SSLContext]:
    with tempfile.TemporaryDirectory(prefix="servoamp-tls-") as d:
        os.chmod(d, 0o700)
        return make_tls(Path(d))


def text_frame(payload: bytes) -> bytes:
    """A client's (masked) text frame."""
    mask = os.urandom(4)
    n = len(payload)
    if n < 126:
        hdr = bytes([0x81, 0x80 | n])
    elif n < 65536:
        hdr = bytes([0x81, 0x80 | 126]) + struct.pack(">H", n)
    else:
        hdr = bytes([0x81, 0x80 | 127]) + struct.pack(">Q", n)
    return hdr + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(payload))


def strip_token(target: str) -> tuple[str, str | None]:
    """The request target without its token parameter, and the token
    (HeadError for a target no URL parser takes, such as ``//[``)."""
    try:
        u = urlsplit(target)
    except ValueError as e:
        raise HeadError(f"bad request target {target[:80]!r}: {e}") from None
    q = parse_qsl(u.query, keep_blank_values=True)
    tok = next((v for k, v in q if k == "token"), None)
    rest = [(k, v) for k, v in q if k != "token"]
    return urlunsplit(("", "", u.path or "/", urlencode(rest), u.fragment)), tok


class WsFront:
    """Listens on (host, port); relays each accepted client to upstream_rw
    (token) or upstream_ro (no token, allowed origin) on 127.0.0.1 over TLS."""

    def __init__(self, host: str, port: int, *, upstream_rw: int, upstream_ro: int,
                 tls: ssl.SSLContext, token: str, origins: tuple[str, ...] | list[str],
                 vouch: Callable[[], str] | None = None, log: bool = True) -> None:
        self.up_rw, self.up_ro = upstream_rw, upstream_ro
        self.vouch = vouch
        self.tls = tls
        self.token = token
        self.origins = tuple(origins)
        self.log = log
        fam = socket.AF_INET6 if ":" in host else socket.AF_INET
        self.lsock = socket.create_server((host.strip("[]"), port), family=fam, backlog=16)
        self.port: int = self.lsock.getsockname()[1]
        self.stopping = threading.Event()
        self.refused_origins: set[str] = set()
        self.refused = 0
        self.accepted_rw = 0
        self.accepted_ro = 0
        self.lock = threading.Lock()
        self.conns: set[socket.socket] = set()
        self.thread = threading.Thread(target=self._accept, name="ws-front", daemon=True)
        self.thread.start()

    def close(self) -> None:
        self.stopping.set()
        try:
            self.lsock.close()
        except OSError:
            pass
        with self.lock:
            conns = list(self.conns)
        for s in conns:
            try:
                s.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
        self.thread.join(timeout=2)

    def _say(self, msg: str) -> None:
        if self.log:
            print(f"servoamp bridge: {msg}", file=sys.stderr, flush=True)

    def _accept(self) -> None:
        self.lsock.settimeout(0.2)
        while not self.stopping.is_set():
            try:
                c, _addr = self.lsock.accept()
            except socket.timeout:
                continue
            except OSError:
                return
            with self.lock:
                full = len(self.conns) >= MAX_CONNS
                if not full:
                    self.conns.add(c)
            if full:
                c.settimeout(1.0)
                _answer(c, 503, "Service Unavailable",
                        f"servoamp bridge: {MAX_CONNS} connections already")
                c.close()
                continue
            threading.Thread(target=self._serve, args=(c,), name="ws-front-conn",
                             daemon=True).start()

    # -- one client --------------------------------------------------------------------
    def decide(self, head: Head) -> tuple[str, str]:
        """('rw' | 'ro' | 'refuse', why)."""
        if head.method != "GET" or (head.get("upgrade") or "").lower() != "websocket":
            return "bad", "a WebSocket upgrade (GET, Upgrade: websocket) is expected"
        _target, tok = strip_token(head.target)
        origin = head.get("origin")
        if tok is not None:
            if hmac.compare_digest(tok.encode(), self.token.encode()):
                return "rw", "token"
            return "refuse", "wrong token"
        if origin is None:
            return "ro", "no Origin (not a browser)"
        if origin_allowed(origin, self.origins):
            return "ro", f"origin {origin} allowed"
        return "refuse", (f"origin {origin} is not allowed: open the URL servoamp bridge "
                          f"printed (with its token), or start the bridge with "
                          f"--allow-origin {origin}")

    def _serve(self, c: socket.socket) -> None:
        up: ssl.SSLSocket | None = None
        try:
            try:
                raw, rest = read_head(c, timeout=HEAD_TIMEOUT_S)
                head = parse_head(raw)
                kind, why = self.decide(head)
            except HeadError as e:
                c.settimeout(HEAD_TIMEOUT_S)
                _answer(c, 400, "Bad Request", f"servoamp bridge: {e}")
                return
            c.settimeout(HEAD_TIMEOUT_S)
            if kind == "bad":
                _answer(c, 400, "Bad Request", f"servoamp bridge: {why}")
                return
            if kind == "refuse":
                with self.lock:
                    self.refused += 1
                    first = why not in self.refused_origins
                    self.refused_origins.add(why)
                if first:
                    self._say(f"WebSocket client refused: {why}")
                _answer(c, 403, "Forbidden", f"servoamp bridge: {why}")
                return
            target, _tok = strip_token(head.target)
            head.target = target
            offered = [p.strip() for p in (head.get("sec-websocket-protocol") or "").split(",")
                       if p.strip()]
            renamed = SUBPROTOCOL not in offered and SUBPROTOCOL_OLD in offered
            if renamed:
                head.replace("Sec-WebSocket-Protocol", SUBPROTOCOL)
            port = self.up_rw if kind == "rw" else self.up_ro
            try:
                raw_up = socket.create_connection(("127.0.0.1", port), timeout=HEAD_TIMEOUT_S)
                up = self.tls.wrap_socket(raw_up, server_hostname="127.0.0.1")
                up.sendall(head.encode() + rest)
                rhead_raw, rrest = read_head(up)
            except (OSError, HeadError) as e:
                _answer(c, 502, "Bad Gateway", f"servoamp bridge: its server did not answer: {e}")
                return
            rhead = rhead_raw.decode("latin-1").split("\r\n")
            if renamed:
                rhead = [f"Sec-WebSocket-Protocol: {SUBPROTOCOL_OLD}"
                         if ln.lower().startswith("sec-websocket-protocol:") else ln
                         for ln in rhead]
            upgraded = rhead[0].split(" ")[1:2] == ["101"]
            if upgraded and kind == "rw" and self.vouch is not None:
                # before any byte of the client's: the server marks this
                # connection as the token's (servoamp.bridge_params)
                up.sendall(text_frame(json.dumps({"op": "getParameters", "parameterNames": [],
                                                  "id": self.vouch()}).encode()))
            c.sendall(("\r\n".join(rhead) + "\r\n\r\n").encode("latin-1") + rrest)
            if not upgraded:
                return
            with self.lock:
                if kind == "rw":
                    self.accepted_rw += 1
                else:
                    self.accepted_ro += 1
            self._relay(c, up)
        except OSError:
            pass
        finally:
            with self.lock:
                self.conns.discard(c)
            if up is not None:
                try:  # TLS's close_notify, so the SDK sees an orderly close
                    up.settimeout(1.0)
                    up = up.unwrap()  # type: ignore[assignment]
                except (OSError, ValueError):
                    pass
            for s in (up, c):
                if s is not None:
                    try:
                        s.close()
                    except OSError:
                        pass

    def _relay(self, c: socket.socket, up: ssl.SSLSocket) -> None:
        c.settimeout(STALL_TIMEOUT_S)
        up.settimeout(STALL_TIMEOUT_S)
        sel = selectors.DefaultSelector()
        sel.register(c, selectors.EVENT_READ, up)
        sel.register(up, selectors.EVENT_READ, c)
        try:
            while not self.stopping.is_set():
                # TLS may hold decrypted bytes the socket no longer signals
                ready: list[tuple[socket.socket, socket.socket]] = []
                if up.pending():
                    ready.append((up, c))
                else:
                    ready = [(k.fileobj, k.data) for k, _ev in sel.select(0.5)]  # type: ignore[misc]
                for src, dst in ready:
                    try:
                        data = src.recv(1 << 16)
                    except ssl.SSLWantReadError:
                        continue
                    if not data:
                        return
                    dst.sendall(data)
        except (OSError, ValueError):
            return
        finally:
            sel.close()
