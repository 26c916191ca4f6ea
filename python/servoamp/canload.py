"""Bus load of a logged CAN bus, cycle by cycle.

Reads a python-can log (ASC or BLF, e.g. from ``python -m can.logger -i
servoamp``; docs/fieldbus.md) whose timestamps are guest time, and cuts the
bus at each SYNC (COB-ID 0x080): the bits of a cycle are the exact frame
lengths (:func:`servoamp.canlink.frame_bits`, stuff bits counted) of the
frames from one SYNC up to the next, and the cycle's load is those bits
times the bit time over the period.

    python -m servoamp.canload build/demo/can0.asc [--bitrate 1000000]
"""

from __future__ import annotations

import argparse
import re
import statistics
import sys
from dataclasses import dataclass
from pathlib import Path

import can

from servoamp import canlink

SYNC_ID = 0x080

# The CANopen master's counters, one line per bus per statistics interval on
# the servo core's UART (rpu_app/src/canopen_master.c, docs/fieldbus.md).
MASTER_FIELDS = ("bus", "nodes_op", "sync", "sync_missed", "rpdo", "rpdo_missed", "tpdo",
                 "pdo_missing", "pdo_missing_max", "emcy", "hb_timeouts", "faults", "sdo_ok",
                 "sdo_fail", "rx_bad", "pdo_timeouts", "nmt_left", "start_retries", "fault_resets",
                 "reset_refused")
_MASTER_RE = re.compile(r"^stats can=(\d+) " + " ".join(f"{f}=" + r"(\d+)" for f in MASTER_FIELDS[1:])
                        + r"\r?$", re.M)


# The CAN controller driver's counters (rpu_app/src/canps.c), the line after
# the master's: frames, interrupts, error counters and states, bus off.
CONTROLLER_FIELDS = ("bus", "tx", "tx_busy", "rx", "rx_dropped", "rx_fifo_overflow", "ring_max",
                     "irqs", "errors", "tec", "rec", "error_passive", "bus_off", "recoveries")
_CONTROLLER_RE = re.compile(r"^stats canps=(\d+) " + " ".join(f"{f}=" + r"(\d+)" for f in CONTROLLER_FIELDS[1:])
                            + r"\r?$", re.M)


def _stats_lines(rx: re.Pattern[str], fields: tuple[str, ...], text: str,
                 bus: int | None) -> list[dict[str, int]]:
    out = []
    for m in rx.finditer(text):
        d = dict(zip(fields, map(int, m.groups())))
        if bus is None or d["bus"] == bus:
            out.append(d)
    return out


def controller_stats(text: str, bus: int | None = None) -> list[dict[str, int]]:
    """The CAN driver's ``stats canps=`` lines in ``text``, in order, as
    dicts of CONTROLLER_FIELDS; only bus ``bus``'s if given."""
    return _stats_lines(_CONTROLLER_RE, CONTROLLER_FIELDS, text, bus)


def master_stats(text: str, bus: int | None = None) -> list[dict[str, int]]:
    """The master's ``stats can=`` lines in ``text`` (a UART log, CR LF or
    LF), in order, as dicts of MASTER_FIELDS; only bus ``bus``'s if given."""
    return _stats_lines(_MASTER_RE, MASTER_FIELDS, text, bus)


@dataclass(frozen=True)
class LoggedFrame:
    t: float            # s (guest time)
    can_id: int
    eff: bool
    rtr: bool
    data: bytes

    @property
    def bits(self) -> int:
        return canlink.frame_bits(self.can_id, self.eff, self.rtr, len(self.data) if not self.rtr else 0,
                                  b"" if self.rtr else self.data)


def read_log(path: Path | str) -> list[LoggedFrame]:
    """The data and remote frames of a python-can log, in time order (a
    guest frame reaches a logger when the guest sends it, an answer when
    the bus delivers it: a file may hold them out of order)."""
    out = []
    for m in can.LogReader(str(path)):
        if m.is_error_frame or m.is_fd:
            continue
        out.append(LoggedFrame(float(m.timestamp), int(m.arbitration_id), bool(m.is_extended_id),
                               bool(m.is_remote_frame), bytes(m.data)))
    return sorted(out, key=lambda f: f.t)


@dataclass(frozen=True)
class Load:
    cycles: int             # whole cycles (SYNC to SYNC) seen
    period_s: float         # median SYNC to SYNC
    bits_mean: float        # bits per cycle
    bits_max: int
    load_mean: float        # fraction of the bus's time, per cycle
    load_max: float
    frames_per_cycle: float


def cycle_load(frames: list[LoggedFrame], bitrate: int) -> Load:
    """Bits and load per cycle over the whole cycles of a log."""
    syncs = [i for i, f in enumerate(frames) if f.can_id == SYNC_ID and not f.eff]
    if len(syncs) < 2:
        raise ValueError("fewer than two SYNCs: no whole cycle")
    bits = [sum(f.bits for f in frames[a:b]) for a, b in zip(syncs, syncs[1:])]
    counts = [b - a for a, b in zip(syncs, syncs[1:])]
    period = statistics.median(frames[b].t - frames[a].t for a, b in zip(syncs, syncs[1:]))
    per = period * bitrate
    return Load(len(bits), period, statistics.fmean(bits), max(bits), statistics.fmean(bits) / per,
                max(bits) / per, statistics.fmean(counts))


def describe(name: str, load: Load, bitrate: int) -> str:
    return (f"{name}: {load.cycles} cycles of {load.period_s * 1e6:.0f} us at {bitrate / 1e6:g} Mbit/s: "
            f"{load.frames_per_cycle:.2f} frames, {load.bits_mean:.1f} bits per cycle (max {load.bits_max}), "
            f"bus load {100 * load.load_mean:.1f} % (max {100 * load.load_max:.1f} %)")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m servoamp.canload", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("logs", nargs="+", type=Path, help="python-can log files (.asc, .blf)")
    ap.add_argument("--bitrate", type=int, default=1_000_000, help="bus bit rate (default 1000000)")
    args = ap.parse_args(argv)
    rc = 0
    for p in args.logs:
        try:
            print(describe(str(p), cycle_load(read_log(p), args.bitrate), args.bitrate))
        except (OSError, ValueError) as e:
            print(f"{p}: {e}", file=sys.stderr)
            rc = 1
    return rc


if __name__ == "__main__":
    sys.exit(main())
