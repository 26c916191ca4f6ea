# SPDX-License-Identifier: MIT
"""CiA 402 drives simulated on the host, on the emulated CAN bus of our QEMU
in lockstep (docs/fieldbus.md): ``servoamp-drivesim --socket PATH --nodes 1,2``."""

from servoamp.drivesim.drive import EDS, Drive, FaultKind, Frame, Injection, Nmt

__all__ = ["EDS", "Drive", "FaultKind", "Frame", "Injection", "Nmt"]
