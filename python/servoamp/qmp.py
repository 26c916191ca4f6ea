"""QEMU's machine protocol (QMP) over a unix socket. Part of the launcher
that :mod:`servoamp.qemu` re-exports."""

from __future__ import annotations

import json
import socket
import time
from pathlib import Path
from typing import Any

from servoamp.board import QemuError


def connect_unix(path: Path | str, timeout: float = 10.0, what: str = "socket") -> socket.socket:
    """Connect to a unix socket QEMU is still creating (QMP, gdbstub),
    retrying until ``timeout``; the socket then has that timeout."""
    deadline = time.monotonic() + timeout
    while True:
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            sock.connect(str(path))
            break
        except OSError:
            sock.close()
            if time.monotonic() > deadline:
                raise QemuError(f"{what} {path} did not come up") from None
            time.sleep(0.02)
    sock.settimeout(timeout)
    return sock


class Qmp:
    """A minimal QMP client (JSON lines over a unix socket)."""

    def __init__(self, path: Path, timeout: float = 60.0) -> None:
        # generous: QEMU greets from its main loop, which a host with more
        # busy processes than cores (seen: load 8 on 2 cores) can hold back
        # for over 10 s while the vCPU thread starts
        self._sock = connect_unix(path, timeout, "QMP socket")
        self._file = self._sock.makefile("rwb")
        self._read()  # greeting
        self.execute("qmp_capabilities")

    def _read(self) -> dict[str, Any]:
        while True:
            line = self._file.readline()
            if not line:
                raise QemuError("QMP connection closed")
            msg = json.loads(line)
            if "event" not in msg:
                assert isinstance(msg, dict)
                return msg

    def execute(self, cmd: str, **arguments: Any) -> Any:
        req: dict[str, Any] = {"execute": cmd}
        if arguments:
            req["arguments"] = arguments
        self._file.write(json.dumps(req).encode() + b"\n")
        self._file.flush()
        resp = self._read()
        if "error" in resp:
            raise QemuError(f"QMP {cmd}: {resp['error']}")
        return resp.get("return")

    def close(self) -> None:
        try:
            self._file.close()
            self._sock.close()
        except OSError:
            pass
