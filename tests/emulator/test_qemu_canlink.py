# SPDX-License-Identifier: MIT
"""canlink's QEMU side, the ``can-host-lockstep`` backend
(emulator/qemu/patches/0009, docs/canlink.md), through its qtest (patch
0010, tests/qtest/can-lockstep-test.c) against the build every board test
uses. The qtest starts QEMU with CAN0 on a bus linked to a Unix socket and
is the host side itself:

- exchange: a frame written into CAN0's TX FIFO reaches an active and a
  passive client as FRAME with its id, data, seq and ``t_ns`` = its end on
  the modelled 1 Mbit/s bus (exact stuffed length); the active client's
  answer (FRAME + DONE) is in CAN0's RX FIFO at its own bus end time and not
  1 ns before (``clock_step``), also when it asks for a later start
  (``t_ns``); the passive client gets it as an INFO frame; both get BYE
  when QEMU quits, and the socket file is removed;
- silent-client: an active client that never sends DONE costs timeout-ms
  (300 ms) of host time per frame, its late answer never reaches the
  guest, and after max-timeouts (2) it is disconnected; the next frame
  costs nothing;
- bad-record: a FRAME with dlc 9 between frames, or an answer with an
  identifier over 11 bits, closes that client at once, without holding the
  guest;
- passive-client: never waited for, its DONE ignored; its own frame reaches
  CAN0 at the modelled bus time and the other clients as INFO.
- bus-error, backlog: destroyed frames (patch 0012), a passive client's
  backlog (0013);
- answers-charged, flood, backlog-memory, hello-deadline, bus-order (patch
  0025, issue 36 items 1-5): answers to other clients' frames that QEMU
  had not read yet are not charged to a guest frame (40 of them before one
  DONE keep the client connected); a client that keeps writing costs
  timeout-ms per frame and is dropped after max-timeouts; QEMU's RSS grows
  by less than 2 MiB over 150000 frames to a passive client 20000 records
  behind; idle connections cannot lock the bus out (a HELLO takes the
  oldest idle slot, the rest close after hello-timeout-ms); a logger and a
  listener get SYNC, its answers and the frames after it in bus order.
- arbitration, guest-arbitration (patch 0028, issue 36): the frames that
  answer one guest frame take the bus by CAN priority, whichever of two
  active clients wrote them in whatever order (lower id first, standard
  before extended for the same base id, data before remote); a frame the
  guest sends while an answer waits for the bus wins against it when its
  id is lower. This test checks the order the qtest saw against
  servoamp.canlink.arbitration_key and their bus times against
  frame_bits (back to back from the end of SYNC).

The frame lengths the qtest expects come from servoamp.canlink.frame_bits
(the qtest prints them); this test checks the two agree.

The qtest's frames go on the bus from qtest's register writes, in QEMU's
main loop. On the board they come from a vCPU under ``-icount``: a
bare-metal program (fixtures/canlink_echo.S) on the launcher's machine
(``QemuMachine(can_links=...)``) sends a frame, the drive side
(``servoamp.canlink.Link``, active) answers it, and the program counts its
polls of the RX FIFO until the answer is there: 66 + 58 bit times of guest
time at 1 Mbit/s, 4 instructions (4 ns) per poll.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from servoamp import qemu

REPO = Path(__file__).resolve().parents[2]
HERE = Path(__file__).resolve().parent
LOAD = 0x00100000
RESULT = 0x00200000
CASES = ["exchange", "silent-client", "bad-record", "passive-client", "bus-error", "backlog",
         "answers-charged", "flood", "backlog-memory", "hello-deadline", "bus-order", "arbitration",
         "guest-arbitration"]

pytestmark = pytest.mark.board


@pytest.fixture(scope="module")
def qtest_output() -> str:
    res = subprocess.run([str(REPO / "emulator/qemu/run-regression-test.sh"), str(qemu.project_qemu()),
                          "--test", "can-lockstep-test"],
                         text=True, capture_output=True, timeout=300)
    out = res.stdout + res.stderr
    assert res.returncode == 0, out
    return out


def test_can_lockstep_qtest_passes_on_our_build(qtest_output: str) -> None:
    for case in CASES:
        assert re.search(rf"^ok \d+ .*/can-lockstep/{case}$", qtest_output, re.M), \
            f"{case} did not pass:\n{qtest_output}"
    assert not re.search(r"^not ok", qtest_output, re.M), qtest_output


def test_qtest_bus_times_agree_with_frame_bits(qtest_output: str) -> None:
    """The frame lengths the qtest checks QEMU's times against are the ones
    the host side computes (bus load figures, the drive simulator)."""
    canlink = pytest.importorskip("servoamp.canlink")
    lines = re.findall(r"bits (0x[0-9a-f]+) (std|ext) (data|rtr) (\d+)(?: ([0-9a-f]+))? = (\d+)", qtest_output)
    assert len(lines) == 4, qtest_output
    for can_id, fmt, kind, dlc, data, bits in lines:
        want = canlink.frame_bits(int(can_id, 16), fmt == "ext", kind == "rtr", int(dlc),
                                  bytes.fromhex(data))
        assert int(bits) == want, f"{can_id} {fmt} {kind} {dlc} {data}: qtest {bits}, frame_bits {want}"


def test_qtest_arbitration_order_and_times(qtest_output: str) -> None:
    """The frames of the qtest's arbitration case as a logger got them:
    SYNC, then its seven answers in the order servoamp.canlink's
    arbitration_key gives, each starting where the one before ended."""
    canlink = pytest.importorskip("servoamp.canlink")
    lines = re.findall(r"arbitration: (0x[0-9a-f]+) (std|ext) (data|rtr) (\d+) ([0-9a-f]+|-) at (\d+)",
                       qtest_output)
    assert len(lines) == 8, qtest_output
    frames = [(int(i, 16), fmt == "ext", kind == "rtr", int(dlc), b"" if d == "-" else bytes.fromhex(d), int(t))
              for i, fmt, kind, dlc, d, t in lines]
    assert frames[0][:3] == (0x080, False, False)
    keys = [canlink.arbitration_key(*f[:3]) for f in frames[1:]]
    assert keys == sorted(keys) and len(set(keys)) == len(keys), frames
    for prev, f in zip(frames, frames[1:]):
        assert f[5] - prev[5] == canlink.frame_bits(*f[:5]) * 1000, (prev, f)   # 1 Mbit/s


def _words(m: qemu.QemuMachine, addr: int, n: int) -> list[int]:
    out = m.hmp(f"xp /{n}wx {addr:#x}")
    return [int(w, 16) for w in re.findall(r"0x([0-9a-fA-F]{8})\b", out.split(":", 1)[1])][:n]


def test_guest_frame_answered_at_its_bus_time(tmp_path: Path) -> None:
    """The vCPU's path, under the board's -icount: the guest's frame reaches
    the active and the passive client with its bus end time, the guest waits
    (in guest time) for the answer exactly its modelled bus time, and the
    passive client sees the answer as INFO with the time the guest got it."""
    canlink = pytest.importorskip("servoamp.canlink")
    if not shutil.which("arm-none-eabi-gcc"):
        pytest.skip("arm-none-eabi-gcc missing: run scripts/bootstrap.sh")
    elf = tmp_path / "canlink_echo.elf"
    subprocess.run(["arm-none-eabi-gcc", "-mcpu=cortex-a9", "-nostdlib", "-nostartfiles",
                    f"-Wl,-Ttext={LOAD:#x}", "-o", str(elf), str(HERE / "fixtures" / "canlink_echo.S")],
                   check=True)
    sock = Path(f"/tmp/servoamp-canlink-test-{os.getpid()}.sock")
    extra = ["-S", "-device", f"loader,file={elf},cpu-num=0", "-device", f"loader,addr={LOAD:#x},cpu-num=1"]
    m = qemu.QemuMachine(qemu.Board.load("zynq7000_qemu"), None, run_dir=tmp_path / "qemu", extra_args=extra,
                         clock="virtual", can_links={0: sock}, can_link_opts={"timeout-ms": 10000})
    got: list[Any] = []

    def answer(drive: Any) -> None:
        # its own thread: while QEMU waits for the DONE its main loop (QMP,
        # so m.resume()'s answer) waits too
        frame = drive.recv(timeout=30)
        got.append(frame)
        if frame is not None and frame.type == canlink.FRAME:
            drive.send_frame(0x701, b"\x05")
            drive.done(frame.seq)

    with m.start():
        with canlink.Link.connect(str(sock), active=True, name="drive") as drive, \
                canlink.Link.connect(str(sock), active=False, name="logger") as logger:
            assert drive.bitrate == 1_000_000
            t = threading.Thread(target=answer, args=(drive,), daemon=True)
            t.start()
            m.resume()
            t.join(60)
            assert not t.is_alive() and got, "the drive got no frame"
            frame = got[0]
            assert frame is not None and frame.type == canlink.FRAME, frame
            assert (frame.can_id, frame.eff, frame.rtr, frame.data, frame.seq, frame.info) == \
                (0x181, False, False, b"\x12\x34", 1, False), frame

            seen = logger.recv(timeout=30)
            assert seen == frame, seen
            info = logger.recv(timeout=30)
            assert info is not None and info.info and info.seq == 0, info
            assert (info.can_id, info.data) == (0x701, b"\x05"), info
            answer_bits = canlink.frame_bits(0x701, False, False, 1, b"\x05")
            assert info.t_ns == frame.t_ns + answer_bits * 1000, (frame, info)

            deadline = time.monotonic() + 30
            while (w := _words(m, RESULT, 5))[0] != 1:
                assert time.monotonic() < deadline, f"the guest did not get the answer: {[hex(x) for x in w]}"
                time.sleep(0.05)
    _, polls, rxid, rxdlc, rxdw1 = w
    assert rxid == 0x701 << 21 and rxdlc >> 28 == 1 and rxdw1 == 0x05000000, [hex(x) for x in w]
    # guest time from the TXDW2 store to the answer: the guest frame's bits
    # and the answer's, one ns per instruction, 4 instructions per poll
    frame_bits = canlink.frame_bits(0x181, False, False, 2, b"\x12\x34")
    want_ns = (frame_bits + answer_bits) * 1000
    print(f"guest waited {polls} polls ({polls * 4} ns), bus time {want_ns} ns")
    assert abs(polls * 4 - want_ns) <= 100, f"{polls} polls ({polls * 4} ns), expected {want_ns} ns"
