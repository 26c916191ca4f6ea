"""How long the host held a process off its CPUs: the waits on an emulated
board count the time the guest could run, not the host's clock alone.

A wait for the guest's console (:class:`servoamp.uart.Uart`) used to fail
after N seconds on the host's clock. With two QEMUs, a browser and other
load on two cores, QEMU is runnable but not running for much of that time,
and the guest (on -icount virtual time) does not advance: a 20 s wait for a
shell's echo failed with a guest that had had a few seconds. The kernel
counts that time per thread: the second field of
``/proc/PID/task/TID/schedstat`` is the time the thread spent runnable on a
run queue, waiting for a CPU (Documentation/scheduler/sched-stats.rst). A
wait's time is then its wall time less the longest such wait of any
thread of the processes it depends on (QEMU's, whose vCPU thread runs the
guest and whose main loop moves the UART's bytes; and this process's,
whose reader thread takes them in) over the same span.

A guest that spins without answering still uses its CPU and fails on time;
an idle guest (nothing runnable) counts as running, as its virtual time
then follows the host's. :data:`CAP` bounds every wait in all, however
loaded the host.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterable
from pathlib import Path

#: a wait of N seconds ends after at most CAP * N seconds on the host's
#: clock, even when the host held its processes off for longer
CAP = 8.0


def thread_waits(pids: Iterable[int]) -> dict[tuple[int, int], int] | None:
    """Run-queue wait in ns of every thread of ``pids`` ((pid, tid): ns),
    or None where the kernel keeps no schedstat (then waits use the host's
    clock alone). A process that has gone is left out."""
    out: dict[tuple[int, int], int] = {}
    for pid in pids:
        try:
            tids = os.listdir(f"/proc/{pid}/task")
        except OSError:
            continue
        for tid in tids:
            try:
                fields = Path(f"/proc/{pid}/task/{tid}/schedstat").read_text().split()
            except OSError:
                if not Path("/proc/self/schedstat").exists():
                    return None
                continue
            if len(fields) >= 2:
                out[(pid, int(tid))] = int(fields[1])
    return out


class StallMeter:
    """Measures, from a mark, how long the host held the threads of
    ``pids()`` off its CPUs (the longest single thread's wait)."""

    def __init__(self, pids: Callable[[], Iterable[int]]) -> None:
        self._pids = pids

    def mark(self) -> dict[tuple[int, int], int] | None:
        return thread_waits(self._pids())

    def held_s(self, mark: dict[tuple[int, int], int] | None) -> float:
        """Seconds the host held the most delayed thread off since ``mark``
        (a thread started since counts from 0)."""
        if mark is None:
            return 0.0
        now = thread_waits(self._pids())
        if not now:
            return 0.0
        return max(ns - mark.get(key, 0) for key, ns in now.items()) / 1e9


#: a meter of no process: a Deadline on the host's clock alone
NO_STALL = StallMeter(lambda: ())


def process_tree(root: int) -> list[int]:
    """``root`` and all its descendants (from /proc/*/stat's parent pids)."""
    kids: dict[int, list[int]] = {}
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            stat = Path(f"/proc/{d}/stat").read_text()
        except OSError:
            continue
        ppid = int(stat[stat.rindex(")") + 2:].split()[1])
        kids.setdefault(ppid, []).append(int(d))
    out, todo = [], [root]
    while todo:
        pid = todo.pop()
        out.append(pid)
        todo.extend(kids.get(pid, ()))
    return out


class Deadline:
    """``timeout`` seconds of the time the processes of ``meter`` could run
    (default: this process and its children: QEMU, a browser, a feed):
    expired once that much has passed less the host's hold-offs
    (:class:`StallMeter`), or CAP * timeout in all. The one form of that
    rule: the console's waits (:class:`servoamp.uart.Uart`) use it too."""

    def __init__(self, timeout: float, meter: StallMeter | None = None) -> None:
        self.timeout = timeout
        self.meter = meter or StallMeter(lambda: process_tree(os.getpid()))
        self._t0 = time.monotonic()
        self._mark = self.meter.mark()

    def wall(self) -> float:
        """Seconds on the host's clock since the deadline was set."""
        return time.monotonic() - self._t0

    def held(self) -> float:
        """Seconds the host held the meter's processes off since then."""
        return self.meter.held_s(self._mark)

    def left(self) -> float:
        """Seconds on the host's clock before it can expire; 0 once it has.
        The hold-offs are read only once the timeout has passed on the
        host's clock."""
        wall = self.wall()
        if wall < self.timeout:
            return self.timeout - wall
        if wall >= CAP * self.timeout:
            return 0.0
        return max(0.0, min(self.timeout - (wall - self.held()), CAP * self.timeout - wall))

    def expired(self) -> bool:
        return self.left() <= 0.0

    def describe(self) -> str:
        return (f"{self.timeout:g} s; {self.wall():.1f} s in all, "
                f"{self.held():.1f} s of it held off the CPUs by the host")
