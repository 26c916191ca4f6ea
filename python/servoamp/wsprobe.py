"""What a web page of some origin gets from a WebSocket port: the upgrade
request a browser sends (with its Origin header), and a client's masked
text frame. For the checks of the bridge's front (tests/recorder/
test_bridge_access.py, tests/robot/test_bridge_board.py) and for anyone who
wants to see what a page of their origin would get:

    python -m servoamp.wsprobe 127.0.0.1 8765 https://evil.example
"""

from __future__ import annotations

import base64
import os
import socket
import ssl
import sys

from servoamp.wsfront import HeadError, read_head, text_frame  # noqa: F401 (text_frame: for the tests)


def upgrade(port: int, target: str = "/", origin: str | None = None,
            protocol: str = "foxglove.sdk.v1", host: str = "127.0.0.1",
            timeout: float = 10.0, tls: ssl.SSLContext | None = None) -> tuple[int, str, socket.socket]:
    """Sends a browser's upgrade request: (HTTP status, the answer's head
    and body as read, the socket, left open). With tls, over TLS in that
    context (a local process need not verify anything)."""
    s = socket.create_connection((host, port), timeout=timeout)
    if tls is not None:
        s = tls.wrap_socket(s, server_hostname=host)
    key = base64.b64encode(os.urandom(16)).decode()
    lines = [f"GET {target} HTTP/1.1", f"Host: {host}:{port}", "Upgrade: websocket",
             "Connection: Upgrade", f"Sec-WebSocket-Key: {key}", "Sec-WebSocket-Version: 13",
             f"Sec-WebSocket-Protocol: {protocol}"]
    if origin is not None:
        lines.append(f"Origin: {origin}")
    s.sendall(("\r\n".join(lines) + "\r\n\r\n").encode())
    try:
        raw, rest = read_head(s)
    except HeadError:
        return 0, "", s
    head = raw.decode("latin-1")
    status = int(head.split(" ")[1]) if head.startswith("HTTP/") and " " in head else 0
    return status, head + "\r\n\r\n" + rest.decode("latin-1", "replace"), s


def main(argv: list[str] | None = None) -> int:
    a = sys.argv[1:] if argv is None else argv
    if len(a) not in (2, 3):
        print("usage: python -m servoamp.wsprobe HOST PORT [ORIGIN]", file=sys.stderr)
        return 2
    status, text, s = upgrade(int(a[1]), origin=a[2] if len(a) == 3 else None, host=a[0])
    s.close()
    print(text.strip())
    return 0 if status == 101 else 1


if __name__ == "__main__":
    raise SystemExit(main())
