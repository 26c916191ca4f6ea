"""Robot Framework keywords for the emulated servoamp board.

Use it as ``Library    servoamp.robot.EmulatedBoard``. The keyword names
follow Renode's (``Create Terminal Tester``, ``Wait For Line On Uart``,
``Wait For Prompt On Uart``, ``Write Line To Uart``, ``Execute Command``)
so that a suite reads the same on both emulators; behind them is QEMU
(:mod:`servoamp.qemu`), not Renode.
"""

from servoamp.robot.library import EmulatedBoard

__all__ = ["EmulatedBoard"]
