"""Helpers for the recorder tests: build the telemetry code, run telem_feed."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
from pathlib import Path
from typing import Any

TOP = Path(__file__).resolve().parents[2]
BUILD = TOP / "build" / "telemetry"
VERIFY = TOP / "tools" / "mcap-verify" / "verify.mjs"
PY = sys.executable


def make(san: str = "none", *targets: str) -> Path:
    subprocess.run(["make", "-s", "-C", str(TOP / "linux" / "telemetry"), f"SAN={san}",
                    *targets], check=True)
    return BUILD / san


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Feed:
    """telem_feed running in the background; .port once listening; .result() at the end."""

    def __init__(self, binary: Path, *args: str, port: int = 0, env: dict[str, str] | None = None
                 ) -> None:
        self.proc = subprocess.Popen([str(binary), "--addr", "127.0.0.1", "--port", str(port),
                                      *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True, env=env)
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline()
        if not line.startswith("listening"):
            self.proc.kill()
            raise RuntimeError(f"telem_feed did not start: {line!r} {self.proc.stderr.read()}")
        self.port = int(line.split()[2])

    def result(self, timeout: float = 60) -> dict[str, Any]:
        out, err = self.proc.communicate(timeout=timeout)
        assert self.proc.returncode == 0, (self.proc.returncode, out, err)
        assert "Sanitizer" not in err and "runtime error" not in err, err
        return dict(json.loads(out.strip().splitlines()[-1]))

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.communicate()


def node_verify(path: Path, stream: bool = False) -> dict[str, Any]:
    cmd = ["node", str(VERIFY)] + (["--stream"] if stream else []) + [str(path)]
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=120,
                       env=dict(os.environ, NODE_NO_WARNINGS="1"))
    assert p.returncode == 0, p.stdout + p.stderr
    return dict(json.loads(p.stdout))


def servoamp_cmd(*args: str) -> list[str]:
    return [PY, "-m", "servoamp.cli", *args]


class ScriptedServer:
    """A telemetry server on 127.0.0.1 speaking the wire protocol of
    docs/telemetry.md from a script: it accepts a connection, reads the
    client's AUTH frame (and closes on a wrong token, as servod does), sends
    the bytes of the next script entry, then holds the connection open until
    the client closes it (or close_after is set for that entry). Used where the
    real server cannot be made to misbehave: short and garbled frames, a stream
    of nothing but events."""

    def __init__(self, scripts: list[bytes], token: bytes = b"",
                 close_after: list[bool] | None = None) -> None:
        import threading

        self.scripts = scripts
        self.token = token
        self.close_after = close_after or [False] * len(scripts)
        self.lsock = socket.socket()
        self.lsock.bind(("127.0.0.1", 0))
        self.lsock.listen(4)
        self.port = int(self.lsock.getsockname()[1])
        self.served = 0
        self.auth_failed = 0
        self.done = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _read_exact(self, c: socket.socket, n: int) -> bytes:
        b = b""
        while len(b) < n:
            d = c.recv(n - len(b))
            if not d:
                raise ConnectionError("client closed")
            b += d
        return b

    def _run(self) -> None:
        from servoamp import telemetry as tw

        self.lsock.settimeout(0.2)
        while not self.done.is_set() and self.served < len(self.scripts):
            try:
                c, _ = self.lsock.accept()
            except socket.timeout:
                continue
            with c:
                try:
                    c.settimeout(30)
                    typ, flags, ln = tw.FRAME.unpack(self._read_exact(c, tw.FRAME.size))
                    tok = self._read_exact(c, ln) if ln <= tw.TOKEN_MAX else b""
                    if typ != tw.MSG_AUTH or flags or tok != self.token:
                        self.auth_failed += 1
                        continue
                    i = self.served
                    c.sendall(self.scripts[i])
                    self.served += 1
                    if self.close_after[i]:
                        continue
                    c.settimeout(0.2)
                    while not self.done.is_set():  # hold until the client goes
                        try:
                            if not c.recv(4096):
                                break
                        except socket.timeout:
                            continue
                except (ConnectionError, OSError):
                    continue

    def close(self) -> None:
        self.done.set()
        self.thread.join(timeout=10)
        self.lsock.close()
