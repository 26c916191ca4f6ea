# SPDX-License-Identifier: MIT
"""rpu_app overloaded, in QEMU without Linux (issue 13, finding 11): the
firmware's debug hooks (struct link_debug, written here through the
gdbstub by symbol, as SP_CMD_DEBUG sets them on the board) make the cycle
handlers run back to back, or start a stray level interrupt the firmware
has no handler for. Either way the background loop used to starve: STOP
was never seen and nothing was reported. Now STOP is honoured from the
cycle handler, and an unknown interrupt is disabled at the distributor
and counted on the stats line. No timed assertion: every wait is for a
state the firmware reaches (a word, a console line), with a generous
host-time limit only against hanging forever."""
from __future__ import annotations

import re
from pathlib import Path

import pytest
from rpu_common import PRKD, RUN, qemu_ok
from qemu_rpu import QemuRpu, _symbol as symbol
from test_rpu_qemu import STATS_RE, entry_of, park_range, request_start, request_stop

pytestmark = [pytest.mark.skipif(qemu_ok() is not None, reason=qemu_ok() or ""),
              pytest.mark.on_board("zynq7000_qemu")]

# struct link_debug (rpu_app/src/link.h): word offsets
DBG_OVERLOAD, DBG_STRAY = 4, 8
LINK_RE = (r"^stats link=\w+ attached=\d hb=\d+ spurious=\d+ unhandled=(\d+) "
           r"irq_disabled=(\d+) irq_disabled_last=(\d+)")


def poke(q: QemuRpu, addr: int, value: int) -> None:
    """Write a firmware word as the test's hostile hand (VM stopped, CPU0's
    view: MMU off, physical = the firmware's identity-mapped address)."""
    g = q.attach_gdb()
    g.interrupt()
    g.select_cpu(0)
    g.write32(addr, value)
    g.cont()


def stats_count(q: QemuRpu) -> int:
    return len(re.findall(STATS_RE, q.uart_text(), re.M))


def test_overloaded_core_still_parks_on_stop(rpu_build: Path, board_cfg: dict[str, int], tmp_path: Path) -> None:
    """Cycle handlers back to back (each ends with its interrupt pending
    again, SP_DEBUG_OVERLOAD): the background loop never runs, so the STOP
    word is seen by the cycle handler or not at all. The core must park,
    and a new start must run normally (the hook is cleared at start)."""
    elf = rpu_build / "servo.elf"
    dbg = symbol(elf, "link_debug")
    status = board_cfg["BOARD_STOP_STATUS_ADDR"]
    lo, hi = park_range(rpu_build)
    with QemuRpu(tmp_path / "q", rpu_build / "qemu-stub.elf", elf) as q:
        q.wait_uart(r"^running:", timeout=8)
        q.wait_uart(STATS_RE, timeout=8)
        poke(q, dbg + DBG_OVERLOAD, 1)
        q.wait_word(dbg + DBG_OVERLOAD, 2, timeout=5)  # a handler re-pended itself
        request_stop(q, board_cfg)
        q.wait_word(status, PRKD, timeout=10)
        assert lo <= q.cpu_pc(1) < hi
        q.wait_uart(r"^stop: STOP seen in the cycle handler after \d+ cycles", timeout=3)
        n = stats_count(q)
        request_start(q, board_cfg, entry_of(elf))
        q.wait_word(status, RUN, timeout=3)
        q.wait_uart(r"^running:", count=2, timeout=5)
        q.wait_uart(STATS_RE, count=n + 1, timeout=8)
        assert q.read_word(dbg + DBG_OVERLOAD) == 0


def test_unknown_interrupt_storm_is_disabled_and_counted(rpu_build: Path, board_cfg: dict[str, int],
                                                        tmp_path: Path) -> None:
    """A level interrupt nobody registered fires at this core and stays
    asserted (SP_DEBUG_STRAY_IRQ: a spare TTC counter, never cleared). It
    is disabled at the GIC distributor when it first fires, counted on the
    stats line, the cycle goes on and STOP still parks the core. Before,
    it was acknowledged and completed forever: the background loop
    starved (no stats line, no STOP)."""
    elf = rpu_build / "servo.elf"
    dbg = symbol(elf, "link_debug")
    status = board_cfg["BOARD_STOP_STATUS_ADDR"]
    stray_id = board_cfg["BOARD_CYCLE_IRQ"] - board_cfg["BOARD_CYCLE_COUNTER"] + \
        (3 - board_cfg["BOARD_CYCLE_COUNTER"] - board_cfg["BOARD_LINUX_CYCLE_COUNTER"])
    with QemuRpu(tmp_path / "q", rpu_build / "qemu-stub.elf", elf) as q:
        q.wait_uart(r"^running:", timeout=8)
        first = q.wait_uart(LINK_RE, timeout=8)[0]
        assert first.groups() == ("0", "0", "0"), first.group(0)
        poke(q, dbg + DBG_STRAY, 1)
        q.wait_word(dbg + DBG_STRAY, 2, timeout=5)  # the storm has started
        q.wait_uart(rf"^debug: stray interrupt {stray_id} ", timeout=5)
        n = stats_count(q)
        cyc = q.wait_uart(STATS_RE, count=n + 2, timeout=10)
        assert int(cyc[n + 1].group(1)) > int(cyc[n].group(1)), "the cycle must go on"
        m = q.wait_uart(LINK_RE, count=n + 2, timeout=5)[n + 1]
        unhandled, disabled, last = map(int, m.groups())
        assert disabled == 1 and last == stray_id, m.group(0)
        assert 1 <= unhandled <= 2, f"a disabled interrupt must not keep firing: {m.group(0)}"
        request_stop(q, board_cfg)
        q.wait_word(status, PRKD, timeout=5)
