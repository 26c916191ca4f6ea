"""What `servoamp bridge --mcap` loses (issue 21, item 2): a real bridge
process against a scripted telemetry server on 127.0.0.1 (tests/recorder/
recorder_helpers.ScriptedServer, the frames of test_record_hostile.py):

* SIGKILL loses at most the last flush interval (1 s by default), whatever
  the traffic: after a stretch of cycles, and after a stretch of nothing but
  events (a stopped or recovering controller), everything sent reaches the
  disk while the bridge runs, and is read back after the kill. The bridge
  before this change wrote 1 MiB chunks with no time-based flush: a file of
  121 bytes, no message;
* a full filesystem (a small tmpfs in a mount namespace of the test's own,
  `unshare --mount --map-root-user`) ends the recording cleanly: one
  message, exit status 5, no traceback, and the file readable up to the last
  flush. The bridge before this change printed an SDK error per message and
  ended in a traceback.

The polling loops wait for the bridge to get somewhere; their deadline only
turns a hang into a failure, it is not what is tested.
"""

from __future__ import annotations

import os
import shutil
import signal
import struct
import subprocess
from pathlib import Path

import pytest
from mcap.exceptions import McapError
from mcap.records import Channel, Message
from mcap.stream_reader import StreamReader

from recorder_helpers import PY, TOP, ScriptedServer, servoamp_cmd
from servoamp import bridge
from servoamp.schemas import servoamp_pb2 as pb
from test_record_hostile import ENV, N_AXES, SESSION, T0, TOKEN, _cycles, _valid_events, _wait_for
from servoamp import telemetry as tw


def _read(path: Path) -> tuple[dict[str, list[bytes]], str | None]:
    """Messages by topic, streamed (no summary needed), and why reading stopped."""
    out: dict[str, list[bytes]] = {}
    topics: dict[int, str] = {}
    if not path.exists():
        return out, "no file"
    stopped = None
    with path.open("rb") as f:
        try:
            for r in StreamReader(f, skip_magic=False).records:
                if isinstance(r, Channel):
                    topics[r.id] = r.topic
                elif isinstance(r, Message):
                    out.setdefault(topics[r.channel_id], []).append(r.data)
        except (McapError, EOFError, ValueError, struct.error) as e:
            # the cut: a record written in part (where depends on the flush
            # the disk filled at), read up to it
            stopped = f"{type(e).__name__}: {e}"
    return out, stopped


def _cycle_numbers(msgs: dict[str, list[bytes]]) -> list[int]:
    return [pb.Cycle.FromString(d).cycle for d in msgs.get(bridge.T_CYCLE, [])]


def _bridge(port: int, out: Path, tmp: Path, *extra: str) -> subprocess.Popen[str]:
    tok = tmp / "token"
    tok.write_bytes(TOKEN + b"\n")
    return subprocess.Popen(servoamp_cmd("bridge", "--connect", f"127.0.0.1:{port}",
                                         "--listen", "127.0.0.1:0", "--mcap", str(out),
                                         "--token-file", str(tok), *extra),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV)


def _kill(bp: subprocess.Popen[str]) -> None:
    bp.kill()
    bp.communicate(timeout=30)
    assert bp.returncode == -signal.SIGKILL


@pytest.mark.parametrize("traffic", ["cycles", "events_only"])
def test_sigkill_loses_at_most_the_flush_interval(tmp_path: Path, traffic: str) -> None:
    if traffic == "cycles":
        n_cycles, k_events = 3000, 0
    else:
        n_cycles, k_events = 5, 40
    script = (tw.encode_hello(N_AXES, SESSION, t_ns=T0) + _cycles(0, n_cycles)
              + b"".join(_valid_events(k) for k in range(k_events)))
    srv = ScriptedServer([script], token=TOKEN)
    out = tmp_path / "kill.mcap"
    bp = _bridge(srv.port, out, tmp_path)
    try:
        def all_there() -> bool:
            msgs, _ = _read(out)
            return (len(_cycle_numbers(msgs)) == n_cycles
                    and len(msgs.get(bridge.T_PARAM, [])) == k_events)
        _wait_for(all_there, bp, f"{n_cycles} cycles and {k_events} events")
        _kill(bp)
    finally:
        if bp.poll() is None:
            bp.kill()
            bp.communicate()
        srv.close()
    msgs, _stopped = _read(out)
    assert _cycle_numbers(msgs) == list(range(n_cycles))
    assert [pb.ParamChange.FromString(d).value for d in msgs.get(bridge.T_PARAM, [])] == \
        [float(k) for k in range(k_events)]
    assert len(msgs.get(bridge.T_LOG, [])) == k_events
    assert len(msgs.get(bridge.T_SESSION, [])) == 1


def test_full_disk_ends_the_recording_cleanly(tmp_path: Path) -> None:
    if shutil.which("unshare") is None:
        pytest.fail("unshare (util-linux) is missing")
    probe = subprocess.run(["unshare", "--mount", "--map-root-user", "true"],
                           capture_output=True, text=True)
    if probe.returncode != 0:
        pytest.skip(f"no mount namespace for this user here: {probe.stderr.strip()}")
    # enough cycles to fill 96 KiB many times over, sent as the bridge reads
    script = tw.encode_hello(N_AXES, SESSION, t_ns=T0) + _cycles(0, 60000)
    srv = ScriptedServer([script], token=TOKEN)
    tok = tmp_path / "token"
    tok.write_bytes(TOKEN + b"\n")
    mnt = tmp_path / "small"
    mnt.mkdir()
    kept = tmp_path / "kept.mcap"
    cmd = " ".join(servoamp_cmd("bridge", "--connect", f"127.0.0.1:{srv.port}", "--listen",
                                "127.0.0.1:0", "--mcap", f"{mnt}/full.mcap", "--token-file",
                                str(tok), "--flush-interval", "0.2"))
    shell = (f"mount -t tmpfs -o size=96k tmpfs {mnt} && {{ {cmd}; rc=$?; "
             f"cp {mnt}/full.mcap {kept}; exit $rc; }}")
    try:
        p = subprocess.run(["unshare", "--mount", "--map-root-user", "sh", "-c", shell],
                           capture_output=True, text=True, timeout=300,
                           env=dict(ENV, PYTHONPATH=str(TOP / "python")))
    finally:
        srv.close()
    err = p.stderr
    assert p.returncode == 5, (p.returncode, p.stdout, err)
    assert "Traceback" not in err, err
    stops = [ln for ln in err.splitlines() if "recording to" in ln and "stopped" in ln]
    assert len(stops) == 1, err
    assert "bytes free" in stops[0] and "readable" in stops[0], stops
    # nothing else but that line and the bridge's own start-up lines
    others = [ln for ln in err.splitlines() if ln.strip() and ln not in stops]
    assert len(others) <= 2, err
    msgs, _stopped = _read(kept)
    cycles = _cycle_numbers(msgs)
    assert len(cycles) > 100, (len(cycles), _stopped)
    assert cycles == list(range(len(cycles)))  # a prefix, in order, no hole
    assert PY  # the interpreter the command line used
    assert os.path.getsize(kept) > 0
