# SPDX-License-Identifier: MIT
"""The bridge's CAN frames (:mod:`servoamp.bridge`, docs/recording.md "CAN
frames"): every frame on each emulated bus, read as a passive canlink
client (QEMU never waits for it), logged on /servoamp/can<bus>
(servoamp.CanFrame). canlink gives a client the frames in bus order
(docs/canlink.md, "Bus order"), so a bus's log times never go back.

Their clock is the emulator's virtual time; their log time is put on the
cycle records' clock (the controller's CLOCK_MONOTONIC) by
:class:`GuestClock` (from the cycle records and the servo core's time
stamps on the bus), so that a frame sits in the cycle it was on the bus in.
Frames read before that clock is known wait (up to CAN_PENDING_MAX) and are
logged, in the order read, once it is. Without servod (``virtual``: a
bare-metal firmware, a qtest) the log time is the virtual time itself.
"""

from __future__ import annotations

import collections
import json
import threading
from pathlib import Path
from typing import Any, Callable, Mapping

from foxglove import Channel, Schema

from servoamp import canlink
from servoamp import telemetry as tw
from servoamp.guestclock import GuestClock
from servoamp.record import RecordResult
from servoamp.schemas import servoamp_pb2 as pb

T_CAN = "/servoamp/can{bus}"   # one per CAN bus: CanFrame
TIME_STAMP_ID = 0x1FF           # the master's time stamp PDO (canopen_master.h CO_COB_TIME_STAMP)
# a CYCLE payload's fixed fields (cycle, t_ns, servo_cycle, t_cycle, irq
# latency, wake-up latency, exchange, ...): the records of any axis count
_CYCLE_HEAD = tw.cycle_struct(0)
# frames held while the clock offset is not known yet (the first cycles)
CAN_PENDING_MAX = 1 << 17


class CanTap:
    """A passive canlink client and a reader thread per bus, logging into
    ``ctx``'s channels; ``on_logged`` is called (under the tap's lock) for
    every frame logged."""

    def __init__(self, ctx: Any, fds: bytes, res: RecordResult, clock: GuestClock,
                 can_links: Mapping[int, str | Path], connect_timeout: float,
                 on_logged: Callable[[], None]) -> None:
        self.res = res
        self.clock = clock
        self.on_logged = on_logged
        self.channels: dict[int, Channel] = {}
        self.errors: dict[int, str] = {}
        self.dropped = 0            # frames over CAN_PENDING_MAX before the clock was known
        self._lock = threading.Lock()
        self._pending: collections.deque[tuple[int, int, bytes]] = collections.deque()
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        links: dict[int, canlink.Link] = {}
        try:
            for bus, path in sorted(can_links.items()):
                try:
                    links[bus] = canlink.Link.connect(str(path), active=False, name="bridge",
                                                      timeout=connect_timeout)
                except (OSError, canlink.ProtocolError) as e:
                    raise ConnectionError(f"CAN bus {bus}: canlink socket {path}: {e}") from e
        except BaseException:
            for lk in links.values():
                lk.close()
            raise
        for bus, lk in links.items():
            self.channels[bus] = Channel(T_CAN.format(bus=bus), message_encoding="protobuf",
                                         context=ctx,
                                         schema=Schema(name="servoamp.CanFrame", encoding="protobuf",
                                                       data=fds))
            self.res.can_frames[bus] = 0
            th = threading.Thread(target=self._loop, args=(bus, lk), daemon=True,
                                  name=f"bridge-can{bus}")
            self._threads.append(th)
            th.start()

    @property
    def ended(self) -> bool:
        """Every bus's reader has ended (QEMU's BYE, or the link failed)."""
        return not any(th.is_alive() for th in self._threads)

    @property
    def wants_cycles(self) -> bool:
        """The cycle records' side of the clock is not known yet."""
        return self.clock.gt_minus_mono_ns is None

    def _loop(self, bus: int, lk: canlink.Link) -> None:
        """Reads one bus until close() or QEMU's BYE. A passive client must
        keep reading: QEMU drops a client whose socket buffer is full."""
        bit_ns = 1e9 / lk.bitrate
        bus_free = 0        # end of the latest frame seen on this bus
        try:
            while not self._stop.is_set():
                rec = lk.recv(0.2)
                if rec is None:
                    continue
                if rec.type == canlink.BYE:
                    break
                if rec.type not in (canlink.FRAME, canlink.ERROR):
                    continue
                error = rec.type == canlink.ERROR       # a frame destroyed by a bus error
                data = rec.data     # exactly dlc bytes, none for a remote frame
                bits = 0 if error else canlink.frame_bits(rec.can_id, rec.eff, rec.rtr, rec.dlc, data)
                msg = pb.CanFrame(bus=bus, t_bus_ns=rec.t_ns, id=rec.can_id, extended=rec.eff,
                                  remote=rec.rtr, dlc=rec.dlc, data=data, bits=bits,
                                  from_servo=not rec.info, error=error).SerializeToString()
                start = rec.t_ns - round(bits * bit_ns)
                stamp = (not error and not rec.info and not rec.eff and not rec.rtr and rec.dlc == 4
                         and rec.can_id == TIME_STAMP_ID and start >= bus_free)
                bus_free = max(bus_free, rec.t_ns)
                with self._lock:
                    if stamp and self.clock.add_stamp(start, int.from_bytes(data, "little")):
                        self._flush_pending()
                    if self.clock.offset_ns is None:
                        if len(self._pending) < CAN_PENDING_MAX:
                            self._pending.append((bus, rec.t_ns, msg))
                        else:
                            self.dropped += 1
                        continue
                    self._log(bus, rec.t_ns, msg)
        except (OSError, canlink.ProtocolError) as e:
            self.errors[bus] = f"CAN bus {bus}: {e}"
        finally:
            lk.close()

    def _log(self, bus: int, t_bus_ns: int, msg: bytes) -> None:
        """Under _lock, the clock known."""
        self.channels[bus].log(msg, log_time=self.clock.to_monotonic(t_bus_ns))
        self.res.can_frames[bus] += 1
        self.on_logged()

    def cycle_sample(self, buf: bytearray, off: int, clock_hz: int) -> None:
        """A cycle record for the frames' clock (fresh exchanges only)."""
        _cyc, t_ns, _sc, t_cycle, _irq, lat, exch = _CYCLE_HEAD.unpack_from(buf, off)[:7]
        if exch != 0:
            return
        with self._lock:
            if self.clock.add_cycle(t_ns, lat, t_cycle, clock_hz):
                self._flush_pending()

    def _flush_pending(self) -> None:
        """Under _lock, the clock just known."""
        while self._pending:
            self._log(*self._pending.popleft())

    def close(self) -> None:
        """Stops the readers (each ends within 0.2 s)."""
        self._stop.set()
        for th in self._threads:
            th.join(timeout=5)
        self._threads = []

    def metadata(self) -> dict[str, str]:
        """For the recording's servoamp.recording metadata."""
        return {"can_frames": json.dumps(self.res.can_frames),
                "can_pending_lost": str(self.dropped + len(self._pending)),
                "can_clock_offset_ns": str(self.clock.offset_ns),
                "can_errors": json.dumps(self.errors)}
