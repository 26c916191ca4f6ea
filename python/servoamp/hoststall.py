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
