# SPDX-License-Identifier: MIT
"""The CiA 402 (IEC 61800-7-201) power drive state machine: controlword
commands, transitions and statusword bits."""

from __future__ import annotations

import enum


class State(enum.IntEnum):
    NOT_READY = 0
    SWITCH_ON_DISABLED = 1
    READY_TO_SWITCH_ON = 2
    SWITCHED_ON = 3
    OPERATION_ENABLED = 4
    QUICK_STOP_ACTIVE = 5
    FAULT_REACTION_ACTIVE = 6
    FAULT = 7


NAMES = {
    State.NOT_READY: "Not ready to switch on",
    State.SWITCH_ON_DISABLED: "Switch on disabled",
    State.READY_TO_SWITCH_ON: "Ready to switch on",
    State.SWITCHED_ON: "Switched on",
    State.OPERATION_ENABLED: "Operation enabled",
    State.QUICK_STOP_ACTIVE: "Quick stop active",
    State.FAULT_REACTION_ACTIVE: "Fault reaction active",
    State.FAULT: "Fault",
}

# statusword bits 0-3, 5, 6 of each state (the rest added by the drive)
SW_READY_TO_SWITCH_ON = 0x0001
SW_SWITCHED_ON = 0x0002
SW_OPERATION_ENABLED = 0x0004
SW_FAULT = 0x0008
SW_VOLTAGE_ENABLED = 0x0010
SW_QUICK_STOP = 0x0020        # 0 = quick stop active
SW_SWITCH_ON_DISABLED = 0x0040
SW_WARNING = 0x0080
SW_REMOTE = 0x0200
SW_TARGET_REACHED = 0x0400
SW_CSP_FOLLOWING = 0x1000     # CSP: the drive follows the target
SW_FOLLOWING_ERROR = 0x2000   # CSP: following error

STATE_BITS = {
    State.NOT_READY: 0x0000,
    State.SWITCH_ON_DISABLED: 0x0040,
    State.READY_TO_SWITCH_ON: 0x0021,
    State.SWITCHED_ON: 0x0023,
    State.OPERATION_ENABLED: 0x0027,
    State.QUICK_STOP_ACTIVE: 0x0007,
    State.FAULT_REACTION_ACTIVE: 0x000F,
    State.FAULT: 0x0008,
}
STATE_MASK = 0x006F

# controlword bits
CW_SWITCH_ON = 0x0001
CW_ENABLE_VOLTAGE = 0x0002
CW_QUICK_STOP = 0x0004        # 0 = quick stop
CW_ENABLE_OPERATION = 0x0008
CW_FAULT_RESET = 0x0080

# the controlword values of the commands, as a master sends them
SHUTDOWN = 0x0006
SWITCH_ON = 0x0007
DISABLE_VOLTAGE = 0x0000
QUICK_STOP = 0x0002
DISABLE_OPERATION = 0x0007
ENABLE_OPERATION = 0x000F
FAULT_RESET = 0x0080


class Command(enum.Enum):
    DISABLE_VOLTAGE = "disable voltage"
    QUICK_STOP = "quick stop"
    SHUTDOWN = "shutdown"
    SWITCH_ON = "switch on"           # also "disable operation" in Operation enabled
    ENABLE_OPERATION = "enable operation"


def command(cw: int) -> Command:
    """The device control command of controlword ``cw`` (bits 0-3); fault
    reset (a rising edge of bit 7) is seen by :func:`transition`."""
    if not cw & CW_ENABLE_VOLTAGE:
        return Command.DISABLE_VOLTAGE          # 0xxx xx0x
    if not cw & CW_QUICK_STOP:
        return Command.QUICK_STOP               # 0xxx x01x
    if not cw & CW_SWITCH_ON:
        return Command.SHUTDOWN                 # 0xxx x110
    if not cw & CW_ENABLE_OPERATION:
        return Command.SWITCH_ON                # 0xxx 0111
    return Command.ENABLE_OPERATION             # 0xxx 1111


def transition(state: State, cw: int, prev_cw: int) -> State:
    """The state after controlword ``cw`` (previous controlword
    ``prev_cw``). Automatic transitions (Not ready -> Switch on disabled,
    Fault reaction active -> Fault, Quick stop active -> Switch on disabled
    once stopped) are the drive's, not here.

    Accepted besides the standard: enable operation (0x0F) in Ready to
    switch on goes to Operation enabled at once (transitions 3 and 4, as
    most drives do)."""
    if state == State.FAULT:
        if cw & CW_FAULT_RESET and not prev_cw & CW_FAULT_RESET:
            return State.SWITCH_ON_DISABLED          # 15
        return state
    if state in (State.NOT_READY, State.FAULT_REACTION_ACTIVE):
        return state
    cmd = command(cw)
    if state == State.SWITCH_ON_DISABLED:
        return State.READY_TO_SWITCH_ON if cmd == Command.SHUTDOWN else state     # 2
    if state == State.READY_TO_SWITCH_ON:
        if cmd in (Command.DISABLE_VOLTAGE, Command.QUICK_STOP):
            return State.SWITCH_ON_DISABLED          # 7
        if cmd == Command.SWITCH_ON:
            return State.SWITCHED_ON                 # 3
        if cmd == Command.ENABLE_OPERATION:
            return State.OPERATION_ENABLED           # 3 + 4
        return state
    if state == State.SWITCHED_ON:
        if cmd in (Command.DISABLE_VOLTAGE, Command.QUICK_STOP):
            return State.SWITCH_ON_DISABLED          # 10
        if cmd == Command.SHUTDOWN:
            return State.READY_TO_SWITCH_ON          # 6
        if cmd == Command.ENABLE_OPERATION:
            return State.OPERATION_ENABLED           # 4
        return state
    if state == State.OPERATION_ENABLED:
        if cmd == Command.DISABLE_VOLTAGE:
            return State.SWITCH_ON_DISABLED          # 9
        if cmd == Command.QUICK_STOP:
            return State.QUICK_STOP_ACTIVE           # 11
        if cmd == Command.SHUTDOWN:
            return State.READY_TO_SWITCH_ON          # 8
        if cmd == Command.SWITCH_ON:
            return State.SWITCHED_ON                 # 5
        return state
    # Quick stop active
    if cmd == Command.DISABLE_VOLTAGE:
        return State.SWITCH_ON_DISABLED              # 12
    if cmd == Command.ENABLE_OPERATION:
        return State.OPERATION_ENABLED               # 16
    return state


def state_of(statusword: int) -> State | None:
    """The state a statusword shows (None if none)."""
    for state, bits in STATE_BITS.items():
        mask = 0x004F if state in (State.NOT_READY, State.SWITCH_ON_DISABLED,
                                   State.FAULT_REACTION_ACTIVE, State.FAULT) else STATE_MASK
        if statusword & mask == bits:
            return state
    return None


def powered(state: State) -> bool:
    """Whether the power stage drives the motor in ``state``."""
    return state in (State.OPERATION_ENABLED, State.QUICK_STOP_ACTIVE,
                     State.FAULT_REACTION_ACTIVE)
