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
