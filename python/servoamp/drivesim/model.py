# SPDX-License-Identifier: MIT
"""Motor and load of one simulated drive: the drive's position loop on a
rigid inertia, acceleration limited by the drive's current limit.

Units: position in counts, velocity counts/s, acceleration counts/s^2,
current in per mille of the rated current (the CiA 402 unit of 0x6078).
The closed loop is a second-order system with natural frequency
``2*pi*bandwidth_hz`` and damping ``damping``:

    a = wn^2 (x_ref - x) + 2 zeta wn (v_ref - v),  |a| <= a_rated * I_max / 1000

stepped with semi-implicit Euler at most 50 us per substep, so one step
per SYNC interval is exact to the float for a given interval: the model is
deterministic in guest time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

SUBSTEP_S = 50e-6
MAX_SUBSTEPS = 20000


@dataclass
class Motor:
    bandwidth_hz: float = 40.0
    damping: float = 0.8
    accel_rated: float = 1e6       # counts/s^2 at the rated current
    max_current_pm: float = 2000.0  # 0x6073, per mille of rated
    pos: float = 0.0
    vel: float = 0.0
    acc: float = 0.0
    jammed: bool = False           # the load seized: the shaft does not move

    @property
    def current_pm(self) -> float:
        """Motor current in per mille of rated (the torque it makes)."""
        return self.acc / self.accel_rated * 1000.0 if self.accel_rated > 0 else 0.0

    def step(self, x0: float, x1: float, dt: float, powered: bool) -> None:
        """Advance ``dt`` seconds. Powered: follow a reference ramping from
        ``x0`` to ``x1`` over the interval (CSP's linear interpolation).
        Unpowered: the holding brake keeps the shaft still."""
        if dt <= 0:
            return
        if not powered:
            self.vel = 0.0
            self.acc = 0.0
            return
        n = min(MAX_SUBSTEPS, max(1, math.ceil(dt / SUBSTEP_S)))
        h = dt / n
        wn = 2 * math.pi * self.bandwidth_hz
        a_max = self.accel_rated * self.max_current_pm / 1000.0
        v_ref = (x1 - x0) / dt
        for i in range(1, n + 1):
            ref = x0 + (x1 - x0) * i / n
            a = wn * wn * (ref - self.pos) + 2 * self.damping * wn * (v_ref - self.vel)
            a = max(-a_max, min(a_max, a))
            self.acc = a
            if self.jammed:
                self.vel = 0.0
                continue
            self.vel += a * h
            self.pos += self.vel * h
