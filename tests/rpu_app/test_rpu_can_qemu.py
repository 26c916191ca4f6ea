# SPDX-License-Identifier: MIT
"""The servo firmware as CANopen master in QEMU, without Linux (issue 22,
item 4): the firmware built for boards/zynq7000_qemu/servo-can.dts (its
four axes on CiA 402 drives, two per bus) runs on CPU1, its CAN buses are
linked in lockstep to the drive simulator on the host (can-host-lockstep,
docs/canlink.md; servoamp-drivesim), and the axes are enabled through the
firmware's debug hook (app_debug.force_enable, written through the
gdbstub: without Linux nobody sends commands). Each drive must go through
NMT, the SDO configuration and the CiA 402 enable sequence to "operation
enabled", with no SYNC missed.

Needs a QEMU with the can-host-lockstep backend ($SERVOAMP_QEMU, else the
project's build) and the drive simulator; skipped otherwise."""
from __future__ import annotations

import contextlib
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from qemu_rpu import QemuRpu, _symbol
from rpu_common import BOARD, REPO, _make

from servoamp import canload

CAN_DTS = REPO / "boards" / BOARD / "servo-can.dts"
pytestmark = pytest.mark.on_board(BOARD)    # the firmware alone in QEMU



def canlink_qemu() -> str:
    """The QEMU binary with the canlink backend, or skip."""
    from servoamp import qemu

    binary = os.environ.get("SERVOAMP_QEMU") or str(qemu.project_qemu() / "bin" / qemu.QEMU_ANY_BOARD)
    if not os.access(binary, os.X_OK):
        pytest.skip(f"{binary}: no QEMU")
    out = subprocess.run([binary, "-object", "help"], capture_output=True, text=True, timeout=60).stdout
    if "can-host-lockstep" not in out:
        pytest.skip(f"{binary} has no can-host-lockstep backend (docs/canlink.md)")
    return binary


def drivesim_ok() -> None:
    try:
        import servoamp.drivesim.__main__  # noqa: F401
    except ImportError as e:
        pytest.skip(f"no drive simulator: {e}")


@pytest.fixture(scope="module")
def can_build(tmp_path_factory, toolchain) -> Path:
    build = tmp_path_factory.mktemp("rpu_can") / BOARD
    r = _make(build, f"DTS={CAN_DTS}")
    assert r.returncode == 0, f"make failed:\n{r.stdout}\n{r.stderr}"
    return build


def test_can_build_links_the_master(can_build):
    """The CAN variant builds; its board config puts the 4 axes on drives."""
    hdr = (can_build / "board_config.h").read_text()
    assert "#define BOARD_CAN_AXES BOARD_U(4)" in hdr
    for sym in ("co_master_cycle", "canps_irq", "axis_can_ops", "app_debug"):
        _symbol(can_build / "servo.elf", sym)


def test_can_firmware_without_drives(can_build, tmp_path):
    """The CAN variant in the project's QEMU with no drive on any bus (and,
    on a QEMU without the CAN controllers, no controller at all): the
    cycle and the statistics keep running, nothing crashes, and each axis
    ends offline with its error code (no boot-up: 0xff01) instead of
    hanging the start-up."""
    from rpu_common import qemu_ok

    why = qemu_ok()
    if why:
        pytest.skip(why)
    with QemuRpu(tmp_path / "q", can_build / "qemu-stub.elf", can_build / "servo.elf") as q:
        q.wait_uart(r"^running:", timeout=30)
        q.wait_uart(r"^stats cycle=", count=3, timeout=60)
        text = q.uart_text()
        assert "FAULT" not in text and "CRSH" not in text
        if "never entered configuration mode" in text:
            return  # a QEMU without the CAN controllers: the axes stay offline
        for i in range(4):
            b, node = divmod(i, 2)
            q.wait_uart(rf"^axis{i}: can{b} node {node + 1}: failed, fault, error ff01 \(cycle \d+, t_us \d+\)$", timeout=30)
        st = re.findall(r"^stats can=0 nodes_op=(\d+) sync=(\d+) sync_missed=(\d+)", q.uart_text(), re.M)
        assert st and int(st[-1][0]) == 0 and int(st[-1][2]) == 0


LINE_RE = r"^axis{i}: can{b} node {node}: {what}, error {err} \(cycle (\d+), t_us (\d+)\)$"


@contextlib.contextmanager
def _rig(can_build: Path, tmp_path: Path, buses: list[int], axes_mask: int, monkeypatch,
         sim_args: tuple[str, ...] = ()):
    """The CAN firmware in QEMU, ``buses`` linked to a drive simulator each
    (nodes 1 and 2), the axes of ``axes_mask`` enabled and seen in
    operation enabled."""
    monkeypatch.setenv("SERVOAMP_QEMU", canlink_qemu())
    drivesim_ok()
    sockdir = Path(tempfile.mkdtemp(prefix="rpucan-"))
    sims = []
    try:
        links = {}
        for b in buses:
            sock = sockdir / f"can{b}.sock"
            links[b] = sock
            log = open(tmp_path / f"drivesim{b}.log", "w")
            sims.append(subprocess.Popen([sys.executable, "-m", "servoamp.drivesim", "--socket", str(sock),
                                          "--nodes", "1,2", "--wait", "120", "-v", *sim_args], stdout=log,
                                         stderr=subprocess.STDOUT, cwd=REPO))
        elf = can_build / "servo.elf"
        with QemuRpu(tmp_path / "q", can_build / "qemu-stub.elf", elf, can_links=links,
                     can_link_opts={"timeout-ms": 2000}) as q:
            q.wait_uart(r"^running:", timeout=30)
            for b in buses:
                q.wait_uart(rf"^can{b}: controller e000{8 + b}000 irq", timeout=5)
            g = q.attach_gdb()
            g.interrupt()
            g.select_cpu(0)
            g.write32(_symbol(elf, "app_debug"), axes_mask)
            g.cont()
            for i in range(4):
                if axes_mask & (1 << i):
                    b, node = divmod(i, 2)
                    q.wait_uart(LINE_RE.format(i=i, b=b, node=node + 1, what="operation enabled", err="0000"),
                                timeout=90)
            yield q
    finally:
        for s in sims:
            s.terminate()
            try:
                s.wait(timeout=10)
            except subprocess.TimeoutExpired:
                s.kill()
        shutil.rmtree(sockdir, ignore_errors=True)


def _run(can_build: Path, tmp_path: Path, buses: list[int], axes_mask: int, monkeypatch) -> str:
    with _rig(can_build, tmp_path, buses, axes_mask, monkeypatch) as q:
        # two whole statistics intervals with every drive enabled (the
        # last line of an interval: the last controller's)
        last = r"^stats canps=1 "
        n0 = len(re.findall(last, q.uart_text(), re.M))
        q.wait_uart(last, count=n0 + 2, timeout=120)
        text = q.uart_text()
        for b in buses:
            st = canload.master_stats(text, b)
            assert len(st) >= 2, text[-3000:]
            s = st[-1]
            assert s["nodes_op"] == 2, s
            assert s["sync_missed"] == 0 and s["sync"] > 1000
            assert s["emcy"] == s["hb_timeouts"] == s["faults"] == s["sdo_fail"] == s["rx_bad"] == 0, s
            assert s["sdo_ok"] == 2 * 13
            # after start-up every SYNC is answered by both drives
            assert s["pdo_missing"] == st[-2]["pdo_missing"], \
                f"TPDOs missing between the last two intervals: {st[-2]} {s}"
            assert s["tpdo"] > 0 and s["rpdo"] > 0
        assert "FAULT" not in text
        return text


def test_two_can_axes_operation_enabled(can_build, tmp_path, monkeypatch):
    """CAN0 linked to two simulated drives (nodes 1 and 2): axes 0 and 1
    reach operation enabled; CAN1 is left without drives."""
    text = _run(can_build, tmp_path, [0], 0x3, monkeypatch)
    print("\n".join(line for line in text.splitlines() if line.startswith(("axis", "can", "stats can"))))


def test_four_can_axes_two_per_bus(can_build, tmp_path, monkeypatch):
    """Both buses, two drives each: all four axes reach operation enabled."""
    _run(can_build, tmp_path, [0, 1], 0xF, monkeypatch)


def test_drive_faults_reach_the_axis(can_build, tmp_path, monkeypatch):
    """Faults injected in the simulated drives (guest time): node 2's
    over-current becomes axis 1's fault with the drive's EMCY code 0x2310
    within 2 cycles; node 1 dropping off the bus faults its axis within 3
    cycles (2 cycles without its TPDO, 0xff06, issue 33), and the heartbeat
    consumer (60 ms, producer 20 ms) then names it silent: 0x8130."""
    t_oc, t_off = 1.0, 1.5
    with _rig(can_build, tmp_path, [0], 0x3, monkeypatch,
              ("--fault", f"2:over-current@{t_oc}", "--fault", f"1:off-bus@{t_off}")) as q:
        en = [int(m.group(2)) for m in re.finditer(LINE_RE.format(i=r"\d", b=0, node=r"\d",
                                                                 what="operation enabled", err="0000"),
                                                   q.uart_text(), re.M)]
        assert max(en) < t_oc * 1e6, f"drives enabled only at t_us {en}: after the injections"
        oc = q.wait_uart(LINE_RE.format(i=1, b=0, node=2, what=r"[a-z ]+, fault", err="2310"), timeout=180)[0]
        pdo = q.wait_uart(LINE_RE.format(i=0, b=0, node=1, what=r"[a-z ]+, fault", err="ff06"), timeout=180)[0]
        off = q.wait_uart(LINE_RE.format(i=0, b=0, node=1, what=r"[a-z ]+, fault", err="8130"), timeout=180)[0]
        t1, t0, tp = int(oc.group(2)), int(off.group(2)), int(pdo.group(2))
        print(f"off the bus at t_us {t_off * 1e6:.0f}: no TPDO fault at t_us {tp}")
        assert 0 <= tp - t_off * 1e6 <= 3_000 + 1_000
        print(f"over-current seen at t_us {t1} (injected {t_oc * 1e6:.0f}); silence caught at t_us {t0} "
              f"(injected {t_off * 1e6:.0f})")
        assert 0 <= t1 - t_oc * 1e6 <= 2_000 + 1_000
        assert 40_000 <= t0 - t_off * 1e6 <= 60_000 + 1_000 + 1_000
