"""The emulator's virtual time on the controller's clock, for the bridge's
CAN frames (:mod:`servoamp.bridge`, docs/recording.md "CAN frames")."""

from __future__ import annotations


class GuestClock:
    """The emulator's virtual time (ns since the machine's reset, the clock
    of canlink frames) on the controller's CLOCK_MONOTONIC (the clock of
    the cycle records), through the servo core's global timer (gt), which
    both sides see:

    * gt - monotonic, from the cycle records: a fresh record holds the
      cycle interrupt in both clocks (servod's wake-up ``t_ns`` minus its
      wake-up latency, and ``t_cycle``, the servo core's global timer at
      ``clock_hz``, 32 bits, at the start of the same cycle). The median of
      the first SAMPLES records. Each ``t_cycle`` is unwrapped to the value
      nearest the event: on the Zynq-7000 Linux's clocksource is the same
      timer (the two differ by milliseconds, not by half a wrap, 21 s at
      100 MHz); on the ZynqMP the R5's cycle counter (1 GHz) starts with the
      firmware and wraps every 4.3 s, so this is known only modulo a wrap.
    * virtual - gt, from the master's time stamp on the bus (CiA 301
      0x1013: the global timer in us, 32 bits, on PDO 0x1FF, the first frame
      of a master's cycle, rpu_app/src/canopen_master.h): sent on an idle
      bus, the frame starts when the servo core writes it, so its start on
      the bus (its end minus its bits at the bit rate) is the stamp in
      virtual time. Linux zeroes the global timer when it takes it as its
      clocksource, so this is not a constant of the emulator; modulo 2^32 us
      (71 min). A stamp behind other frames on the bus is not used.

    Known once both are: a boot's constant, modulo the servo timer's wrap
    (2^32 ticks at ``clock_hz``). The wrap is resolved by the emulator's
    clock and Linux's: both start at the machine's reset or shortly after
    it (Linux's CLOCK_MONOTONIC from its timekeeping's start, a fraction of
    a guest second into the boot), so virtual - monotonic is taken in
    [0, one wrap): 4.3 s at the R5's 1 GHz, 43 s at the A9's 100 MHz."""

    SAMPLES = 33
    WRAP_US = 1 << 32

    def __init__(self) -> None:
        self.samples: list[int] = []
        self.gt_minus_mono_ns: int | None = None
        self.virt_minus_gt_ns: int | None = None
        self.wrap_ns: int | None = None      # 2^32 servo ticks, from the records' clock_hz

    @classmethod
    def virtual(cls) -> GuestClock:
        """No controller's clock (a machine without servod: no cycle
        records): the emulator's virtual time itself, offset 0."""
        c = cls()
        c.gt_minus_mono_ns = c.virt_minus_gt_ns = 0
        c.wrap_ns = 1 << 64      # no servo timer to wrap: 0 stays 0
        return c

    @property
    def offset_ns(self) -> int | None:
        """virtual - monotonic, once known, in [0, wrap_ns)."""
        if self.gt_minus_mono_ns is None or self.virt_minus_gt_ns is None or not self.wrap_ns:
            return None
        return (self.virt_minus_gt_ns + self.gt_minus_mono_ns) % self.wrap_ns

    def add_cycle(self, t_ns: int, wake_latency_ns: int, t_cycle: int, clock_hz: int) -> bool:
        """One fresh cycle record; True when this made the offset known."""
        if self.gt_minus_mono_ns is not None or clock_hz <= 0:
            return False
        event = t_ns - wake_latency_ns
        wrap = 1 << 32
        self.wrap_ns = wrap * 1_000_000_000 // clock_hz
        k = round((event * clock_hz / 1e9 - t_cycle) / wrap)
        gt_ns = (t_cycle + k * wrap) * 1_000_000_000 // clock_hz
        self.samples.append(gt_ns - event)
        if len(self.samples) < self.SAMPLES:
            return False
        self.gt_minus_mono_ns = sorted(self.samples)[len(self.samples) // 2]
        return self.offset_ns is not None

    def add_stamp(self, t_start_ns: int, stamp_us: int) -> bool:
        """A time stamp that started on an idle bus at virtual t_start_ns;
        True when this made the offset known."""
        if self.virt_minus_gt_ns is not None:
            return False
        self.virt_minus_gt_ns = (t_start_ns - stamp_us * 1000) % (self.WRAP_US * 1000)
        return self.offset_ns is not None

    def to_monotonic(self, virt_ns: int) -> int:
        off = self.offset_ns
        assert off is not None
        return max(0, virt_ns - off)
