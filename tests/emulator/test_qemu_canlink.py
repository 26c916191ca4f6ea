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

The frame lengths the qtest expects come from servoamp.canlink.frame_bits
(the qtest prints them); this test checks the two agree.
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

from servoamp import qemu

REPO = Path(__file__).resolve().parents[2]
CASES = ["exchange", "silent-client", "bad-record", "passive-client"]

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
