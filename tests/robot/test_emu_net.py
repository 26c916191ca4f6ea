"""``west emu --net`` end to end: boot with guest networking, bring eth0 up,
and reach a server in the guest through the host forward on 127.0.0.1."""
from __future__ import annotations

import secrets
import socket
import subprocess
import sys
import time
from pathlib import Path

from servoamp import netboard, qemu

REPO = Path(__file__).resolve().parents[2]


def test_emu_net_forwards_the_telemetry_port(images: qemu.Images) -> None:
    board = qemu.Board.load("zynq7000_qemu")
    port = netboard.free_port()
    token = f"emu-net-{secrets.token_hex(4)}"
    guest_port = board.data["network"]["telemetry_port"]
    # the guest answers connections on the telemetry port until one of them
    # says "ok" back, then the scripted run ends. QEMU's user networking
    # accepts a host connection before the guest listens and closes it
    # (nothing read; the host connects again), and the guest's one answer
    # could go to such a connection: the run ended with the host having
    # read nothing (CI, on a loaded host). On the host clock, with a
    # second's pause after the answer: user networking hands the guest's
    # bytes to the host socket from its main loop.
    cmd = [sys.executable, str(REPO / "scripts" / "west_commands" / "emu.py"),
           "--accel", "tcg,thread=single", "--host-time", "--net", str(port), "--timeout", "90",
           "-c", f"until echo {token} | nc -l -p {guest_port} | grep -q ok; do :; done; sleep 1"]
    proc = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    got = b""
    try:
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline and proc.poll() is None and token.encode() not in got:
            try:
                with socket.create_connection(("127.0.0.1", port), timeout=2) as s:
                    s.settimeout(5)
                    got = b""
                    while token.encode() not in got and (chunk := s.recv(256)):
                        got += chunk
                    if token.encode() in got:
                        s.sendall(b"ok\n")  # the guest's cue to end the run
            except OSError:
                pass
            if token.encode() not in got:
                time.sleep(0.5)
        out, _ = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert token.encode() in got, f"nothing from the guest through 127.0.0.1:{port}\n{out[-3000:]}"
    assert proc.returncode == 0, out[-3000:]
    assert f"host 127.0.0.1:{port} -> guest :{guest_port}" in out
    assert "carrier 1" in out
    # where to watch it live (servoamp bridge, docs/recording.md)
    assert f"servoamp bridge --connect 127.0.0.1:{port}" in out and "ws://127.0.0.1:8765" in out
