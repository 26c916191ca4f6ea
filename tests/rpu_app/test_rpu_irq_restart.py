# SPDX-License-Identifier: MIT
"""No interrupt stays active across a restart (issue 20, item 5), in QEMU
without Linux.

The firmware's debug hook (irq_debug_abort, SP_DEBUG_IRQ_ABORT on the board;
written here through the gdbstub by symbol) makes the next cycle interrupt
take a data abort on the SVC stack's guard page right after the dispatcher
acknowledged it at the GIC, before its latency probe. The cycle interrupt
is then active in CPU1's CPU interface (running priority 0xa0): unless it
is completed, neither the cycle interrupt nor the idle wake (0xe0) is ever
taken again, even after a stop and a new start. The firmware used to lose
the acknowledge in that window: the restarted firmware only logged "CPU
interface busy" and ran no cycle at all.

  - the fault handler completes every interrupt acknowledged and not yet
    completed (recorded right after the acknowledge): stop, start, cycles;
  - an interrupt left active without a record (here: the record wiped by
    the test at the fault handler's entry, as a reset or an older firmware
    would leave it) is completed at the next start (the start-up drain).

No timed assertion: every wait is for a state the firmware reaches (a word,
a console line), with a generous host-time limit only against hanging."""
from __future__ import annotations

import contextlib
import re
import socket
import time
from pathlib import Path
from typing import Iterator

import pytest
from rpu_common import CRSH, PRKD, RUN, qemu_ok
from qemu_rpu import GdbRemote, QemuRpu, _symbol as symbol
from test_rpu_qemu import STATS_RE, entry_of, request_start, request_stop

pytestmark = [pytest.mark.skipif(qemu_ok() is not None, reason=qemu_ok() or ""),
              pytest.mark.on_board("zynq7000_qemu")]

BUSY = "CPU interface busy"


def poke(q: QemuRpu, addr: int, value: int) -> None:
    """Write a firmware word (VM stopped; CPU0's view: MMU off, physical =
    the firmware's identity-mapped address)."""
    g = q.attach_gdb()
    g.interrupt()
    g.select_cpu(0)
    g.write32(addr, value)
    g.cont()


def wait_cycles(q: QemuRpu, cycles_addr: int, n: int, timeout: float, what: str) -> None:
    """Until the firmware's cycle counter (.bss, zeroed at every start)
    reaches n; the UART output since the last start in the failure."""
    deadline = time.monotonic() + timeout
    while q.read_word(cycles_addr) < n:
        if time.monotonic() > deadline:
            text = q.uart_text()
            last = text[text.rfind("servoamp rpu_app "):]
            pytest.fail(f"{what}: {q.read_word(cycles_addr)} cycles after {timeout:g} s (want {n}); "
                        f"UART1 since the last start:\n{last[-2500:]}")
        time.sleep(0.01)


def wait_stop_reply(g: GdbRemote, timeout: float) -> str:
    """The stop reply after a breakpoint hit (the VM stopped)."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            reply = g._read_packet()
        except (socket.timeout, TimeoutError):
            if time.monotonic() > deadline:
                raise
            continue
        if reply.startswith(("T", "S")):
            g.running = False
            return reply


def restart(q: QemuRpu, cfg: dict[str, int], entry: int) -> None:
    """What the Linux driver does after a crash: STOP (the fault handler
    parks), then a new start from the park loop."""
    status = cfg["BOARD_STOP_STATUS_ADDR"]
    q.wait_uart(r"^FAULT: waiting for STOP", timeout=5)
    request_stop(q, cfg)
    q.wait_word(status, PRKD, timeout=5)
    request_start(q, cfg, entry)
    q.wait_word(status, RUN, timeout=5)
    q.wait_uart(r"^running:", count=2, timeout=8)


def second_run(q: QemuRpu) -> str:
    text = q.uart_text()
    starts = [m.start() for m in re.finditer(r"^servoamp rpu_app ", text, re.M)]
    assert len(starts) == 2, f"{len(starts)} banners"
    return text[starts[1]:]


def in_service(cfg: dict[str, int], which: str) -> list[tuple[int, int]]:
    """(ID, priority) of the interrupts active at the fault, innermost first:
    the cycle interrupt alone, or the nesting self-test's SGI inside it."""
    cycle = (cfg["BOARD_CYCLE_IRQ"], cfg["BOARD_CYCLE_PRIORITY"])
    if which == "cycle":
        return [cycle]
    return [(cfg["BOARD_NEST_TEST_SGI"], cfg["BOARD_NEST_TEST_PRIORITY"]), cycle]


def arm_abort(g: GdbRemote, elf: Path, irq: int) -> None:
    """The debug hook: the next dispatch of irq faults right after its
    acknowledge (the VM is stopped; CPU0's view: physical addresses)."""
    g.select_cpu(0)
    g.write32(symbol(elf, "irq_debug_abort"), irq + 1)


@contextlib.contextmanager
def running_firmware(rpu_build: Path, elf: Path, cycles: int, tmp_path: Path) -> Iterator[tuple[QemuRpu, GdbRemote]]:
    """The firmware running alone in QEMU, 20 cycles done, CPU1 stopped by
    the gdb stub: (the run, its gdb connection)."""
    with QemuRpu(tmp_path / "q", rpu_build / "qemu-stub.elf", elf) as q:
        q.wait_uart(r"^running:", timeout=8)
        wait_cycles(q, cycles, 20, 10, "first start")
        g = q.attach_gdb()
        g.interrupt()
        yield q, g


WHICH = ["cycle", "nested"]  # the nesting self-test runs once per 1000 cycles


@pytest.mark.parametrize("which", WHICH)
def test_abort_after_ack_is_completed_by_the_fault_handler(rpu_build: Path, board_cfg: dict[str, int],
                                                           tmp_path: Path, which: str) -> None:
    """An interrupt faults right after its acknowledge (the cycle interrupt,
    or the SGI nested in it): the fault handler completes every interrupt in
    service, innermost first, and after stop and start the cycle runs again
    on an idle CPU interface (no "CPU interface busy", nothing to drain)."""
    elf = rpu_build / "servo.elf"
    cycles = symbol(elf, "cycles")
    active = in_service(board_cfg, which)
    with running_firmware(rpu_build, elf, cycles, tmp_path) as (q, g):
        arm_abort(g, elf, active[0][0])
        g.cont()
        q.wait_word(board_cfg["BOARD_STOP_STATUS_ADDR"], CRSH, timeout=10)
        q.wait_uart(r"^FAULT: SVC stack overflow: access at", timeout=5)
        restart(q, board_cfg, entry_of(elf))
        wait_cycles(q, cycles, 2 * board_cfg["BOARD_STATS_CYCLES"], 30, "after the restart")
        q.wait_uart(STATS_RE, count=2, timeout=10)
        text = q.uart_text()
        # in the dispatcher's record (nesting depth), completed by the handler
        assert re.search(rf"^FAULT: data abort at pc=[0-9a-f]{{8}} .* nest={len(active)}$", text, re.M), text[-2500:]
        done = [int(x) for x in re.findall(r"^FAULT: completed irq (\d+) \(acknowledged, in service at the fault\)$",
                                           text, re.M)]
        assert done == [irq for irq, _ in active], text[-2500:]
        run2 = second_run(q)
        assert BUSY not in run2, run2[:2500]
        assert "gic:" not in run2, run2[:2500]
        stats = [m for m in re.finditer(STATS_RE, run2, re.M)]
        assert stats and int(stats[-1].group(9)) == 0, "nesting self-test failed after the restart"


@pytest.mark.parametrize("which", WHICH)
def test_interrupt_left_active_is_drained_at_start(rpu_build: Path, board_cfg: dict[str, int],
                                                   tmp_path: Path, which: str) -> None:
    """The same fault, but the dispatcher's record of the acknowledges is
    wiped at the fault handler's entry (breakpoint), so the interrupts stay
    active through the stop: the next start finds the CPU interface busy,
    completes its own active interrupts innermost first, says so, and the
    cycle runs."""
    elf = rpu_build / "servo.elf"
    cycles = symbol(elf, "cycles")
    active = in_service(board_cfg, which)
    with running_firmware(rpu_build, elf, cycles, tmp_path) as (q, g):
        fr = symbol(elf, "fault_report")
        assert g.command(f"Z0,{fr:x},4") == "OK"
        arm_abort(g, elf, active[0][0])
        g.cont()
        wait_stop_reply(g, 15)
        g.select_cpu(0)
        g.write32(symbol(elf, "nest"), 0)  # the record is lost
        assert g.command(f"z0,{fr:x},4") == "OK"
        g.cont()
        q.wait_word(board_cfg["BOARD_STOP_STATUS_ADDR"], CRSH, timeout=5)
        q.wait_uart(r"^FAULT: data abort at pc=[0-9a-f]{8} .* nest=0$", timeout=5)
        restart(q, board_cfg, entry_of(elf))
        wait_cycles(q, cycles, 2 * board_cfg["BOARD_STATS_CYCLES"], 30, "after the restart")
        run2 = second_run(q)
        done = ", ".join(f"irq {irq} (prio {prio:02x})" for irq, prio in active)
        group = active[0][1] & 0xF8  # running priority: the group priority (BPR 2)
        assert f"gic: CPU interface busy at priority {group:02x} on entry: completed {done}; now ff\n" in run2, \
            run2[:2500]
        assert "error: gic" not in run2
        stats = [m for m in re.finditer(STATS_RE, run2, re.M)]
        assert stats and int(stats[-1].group(9)) == 0, "nesting self-test failed after the restart"
