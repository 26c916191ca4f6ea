from google.protobuf.internal import containers as _containers
from google.protobuf.internal import enum_type_wrapper as _enum_type_wrapper
from google.protobuf import descriptor as _descriptor
from google.protobuf import message as _message
from collections.abc import Iterable as _Iterable, Mapping as _Mapping
from typing import ClassVar as _ClassVar, Optional as _Optional, Union as _Union

DESCRIPTOR: _descriptor.FileDescriptor

class Exchange(int, metaclass=_enum_type_wrapper.EnumTypeWrapper):
    __slots__ = ()
    FRESH: _ClassVar[Exchange]
    STALE: _ClassVar[Exchange]
    TORN: _ClassVar[Exchange]
    MISSED: _ClassVar[Exchange]
    INVALID: _ClassVar[Exchange]
    NONE: _ClassVar[Exchange]
    UNKNOWN: _ClassVar[Exchange]
FRESH: Exchange
STALE: Exchange
TORN: Exchange
MISSED: Exchange
INVALID: Exchange
NONE: Exchange
UNKNOWN: Exchange

class Command(_message.Message):
    __slots__ = ("control_word", "target_pos", "vel_ff", "torque_offset")
    CONTROL_WORD_FIELD_NUMBER: _ClassVar[int]
    TARGET_POS_FIELD_NUMBER: _ClassVar[int]
    VEL_FF_FIELD_NUMBER: _ClassVar[int]
    TORQUE_OFFSET_FIELD_NUMBER: _ClassVar[int]
    control_word: int
    target_pos: int
    vel_ff: int
    torque_offset: int
    def __init__(self, control_word: _Optional[int] = ..., target_pos: _Optional[int] = ..., vel_ff: _Optional[int] = ..., torque_offset: _Optional[int] = ...) -> None: ...

class Feedback(_message.Message):
    __slots__ = ("status_word", "actual_pos", "actual_vel", "current", "following_error")
    STATUS_WORD_FIELD_NUMBER: _ClassVar[int]
    ACTUAL_POS_FIELD_NUMBER: _ClassVar[int]
    ACTUAL_VEL_FIELD_NUMBER: _ClassVar[int]
    CURRENT_FIELD_NUMBER: _ClassVar[int]
    FOLLOWING_ERROR_FIELD_NUMBER: _ClassVar[int]
    status_word: int
    actual_pos: int
    actual_vel: int
    current: int
    following_error: int
    def __init__(self, status_word: _Optional[int] = ..., actual_pos: _Optional[int] = ..., actual_vel: _Optional[int] = ..., current: _Optional[int] = ..., following_error: _Optional[int] = ...) -> None: ...

class Axis(_message.Message):
    __slots__ = ("command", "feedback")
    COMMAND_FIELD_NUMBER: _ClassVar[int]
    FEEDBACK_FIELD_NUMBER: _ClassVar[int]
    command: Command
    feedback: Feedback
    def __init__(self, command: _Optional[_Union[Command, _Mapping]] = ..., feedback: _Optional[_Union[Feedback, _Mapping]] = ...) -> None: ...

class Cycle(_message.Message):
    __slots__ = ("cycle", "servo_cycle", "t_cycle", "irq_latency_ticks", "irq_latency_ns", "wake_latency_ns", "exchange", "missed", "servo_status", "result", "axes")
    CYCLE_FIELD_NUMBER: _ClassVar[int]
    SERVO_CYCLE_FIELD_NUMBER: _ClassVar[int]
    T_CYCLE_FIELD_NUMBER: _ClassVar[int]
    IRQ_LATENCY_TICKS_FIELD_NUMBER: _ClassVar[int]
    IRQ_LATENCY_NS_FIELD_NUMBER: _ClassVar[int]
    WAKE_LATENCY_NS_FIELD_NUMBER: _ClassVar[int]
    EXCHANGE_FIELD_NUMBER: _ClassVar[int]
    MISSED_FIELD_NUMBER: _ClassVar[int]
    SERVO_STATUS_FIELD_NUMBER: _ClassVar[int]
    RESULT_FIELD_NUMBER: _ClassVar[int]
    AXES_FIELD_NUMBER: _ClassVar[int]
    cycle: int
    servo_cycle: int
    t_cycle: int
    irq_latency_ticks: int
    irq_latency_ns: float
    wake_latency_ns: int
    exchange: Exchange
    missed: int
    servo_status: int
    result: int
    axes: _containers.RepeatedCompositeFieldContainer[Axis]
    def __init__(self, cycle: _Optional[int] = ..., servo_cycle: _Optional[int] = ..., t_cycle: _Optional[int] = ..., irq_latency_ticks: _Optional[int] = ..., irq_latency_ns: _Optional[float] = ..., wake_latency_ns: _Optional[int] = ..., exchange: _Optional[_Union[Exchange, str]] = ..., missed: _Optional[int] = ..., servo_status: _Optional[int] = ..., result: _Optional[int] = ..., axes: _Optional[_Iterable[_Union[Axis, _Mapping]]] = ...) -> None: ...

class ParamChange(_message.Message):
    __slots__ = ("cycle", "id", "name", "type", "value", "unit")
    CYCLE_FIELD_NUMBER: _ClassVar[int]
    ID_FIELD_NUMBER: _ClassVar[int]
    NAME_FIELD_NUMBER: _ClassVar[int]
    TYPE_FIELD_NUMBER: _ClassVar[int]
    VALUE_FIELD_NUMBER: _ClassVar[int]
    UNIT_FIELD_NUMBER: _ClassVar[int]
    cycle: int
    id: int
    name: str
    type: str
    value: float
    unit: str
    def __init__(self, cycle: _Optional[int] = ..., id: _Optional[int] = ..., name: _Optional[str] = ..., type: _Optional[str] = ..., value: _Optional[float] = ..., unit: _Optional[str] = ...) -> None: ...

class Stats(_message.Message):
    __slots__ = ("last_cycle", "pushed", "dropped", "drained", "client_lost", "client_events_lost", "events", "events_dropped", "bytes_sent", "ring_high_water", "ring_capacity", "clients", "final", "counters", "cycle_rate_hz")
    class CountersEntry(_message.Message):
        __slots__ = ("key", "value")
        KEY_FIELD_NUMBER: _ClassVar[int]
        VALUE_FIELD_NUMBER: _ClassVar[int]
        key: str
        value: int
        def __init__(self, key: _Optional[str] = ..., value: _Optional[int] = ...) -> None: ...
    LAST_CYCLE_FIELD_NUMBER: _ClassVar[int]
    PUSHED_FIELD_NUMBER: _ClassVar[int]
    DROPPED_FIELD_NUMBER: _ClassVar[int]
    DRAINED_FIELD_NUMBER: _ClassVar[int]
    CLIENT_LOST_FIELD_NUMBER: _ClassVar[int]
    CLIENT_EVENTS_LOST_FIELD_NUMBER: _ClassVar[int]
    EVENTS_FIELD_NUMBER: _ClassVar[int]
    EVENTS_DROPPED_FIELD_NUMBER: _ClassVar[int]
    BYTES_SENT_FIELD_NUMBER: _ClassVar[int]
    RING_HIGH_WATER_FIELD_NUMBER: _ClassVar[int]
    RING_CAPACITY_FIELD_NUMBER: _ClassVar[int]
    CLIENTS_FIELD_NUMBER: _ClassVar[int]
    FINAL_FIELD_NUMBER: _ClassVar[int]
    COUNTERS_FIELD_NUMBER: _ClassVar[int]
    CYCLE_RATE_HZ_FIELD_NUMBER: _ClassVar[int]
    last_cycle: int
    pushed: int
    dropped: int
    drained: int
    client_lost: int
    client_events_lost: int
    events: int
    events_dropped: int
    bytes_sent: int
    ring_high_water: int
    ring_capacity: int
    clients: int
    final: bool
    counters: _containers.ScalarMap[str, int]
    cycle_rate_hz: float
    def __init__(self, last_cycle: _Optional[int] = ..., pushed: _Optional[int] = ..., dropped: _Optional[int] = ..., drained: _Optional[int] = ..., client_lost: _Optional[int] = ..., client_events_lost: _Optional[int] = ..., events: _Optional[int] = ..., events_dropped: _Optional[int] = ..., bytes_sent: _Optional[int] = ..., ring_high_water: _Optional[int] = ..., ring_capacity: _Optional[int] = ..., clients: _Optional[int] = ..., final: _Optional[bool] = ..., counters: _Optional[_Mapping[str, int]] = ..., cycle_rate_hz: _Optional[float] = ...) -> None: ...

class Gap(_message.Message):
    __slots__ = ("reason", "source", "from_cycle", "to_cycle", "lost", "detail")
    REASON_FIELD_NUMBER: _ClassVar[int]
    SOURCE_FIELD_NUMBER: _ClassVar[int]
    FROM_CYCLE_FIELD_NUMBER: _ClassVar[int]
    TO_CYCLE_FIELD_NUMBER: _ClassVar[int]
    LOST_FIELD_NUMBER: _ClassVar[int]
    DETAIL_FIELD_NUMBER: _ClassVar[int]
    reason: str
    source: str
    from_cycle: int
    to_cycle: int
    lost: int
    detail: str
    def __init__(self, reason: _Optional[str] = ..., source: _Optional[str] = ..., from_cycle: _Optional[int] = ..., to_cycle: _Optional[int] = ..., lost: _Optional[int] = ..., detail: _Optional[str] = ...) -> None: ...

class QueueLevels(_message.Message):
    __slots__ = ("levels", "capacity")
    class LevelsEntry(_message.Message):
        __slots__ = ("key", "value")
        KEY_FIELD_NUMBER: _ClassVar[int]
        VALUE_FIELD_NUMBER: _ClassVar[int]
        key: str
        value: int
        def __init__(self, key: _Optional[str] = ..., value: _Optional[int] = ...) -> None: ...
    class CapacityEntry(_message.Message):
        __slots__ = ("key", "value")
        KEY_FIELD_NUMBER: _ClassVar[int]
        VALUE_FIELD_NUMBER: _ClassVar[int]
        key: str
        value: int
        def __init__(self, key: _Optional[str] = ..., value: _Optional[int] = ...) -> None: ...
    LEVELS_FIELD_NUMBER: _ClassVar[int]
    CAPACITY_FIELD_NUMBER: _ClassVar[int]
    levels: _containers.ScalarMap[str, int]
    capacity: _containers.ScalarMap[str, int]
    def __init__(self, levels: _Optional[_Mapping[str, int]] = ..., capacity: _Optional[_Mapping[str, int]] = ...) -> None: ...

class Session(_message.Message):
    __slots__ = ("connection", "controller_id", "session_id", "wire_version", "n_axes", "cycle_period_ns", "clock_hz", "ring_capacity", "realtime_ns")
    CONNECTION_FIELD_NUMBER: _ClassVar[int]
    CONTROLLER_ID_FIELD_NUMBER: _ClassVar[int]
    SESSION_ID_FIELD_NUMBER: _ClassVar[int]
    WIRE_VERSION_FIELD_NUMBER: _ClassVar[int]
    N_AXES_FIELD_NUMBER: _ClassVar[int]
    CYCLE_PERIOD_NS_FIELD_NUMBER: _ClassVar[int]
    CLOCK_HZ_FIELD_NUMBER: _ClassVar[int]
    RING_CAPACITY_FIELD_NUMBER: _ClassVar[int]
    REALTIME_NS_FIELD_NUMBER: _ClassVar[int]
    connection: int
    controller_id: str
    session_id: str
    wire_version: int
    n_axes: int
    cycle_period_ns: int
    clock_hz: int
    ring_capacity: int
    realtime_ns: int
    def __init__(self, connection: _Optional[int] = ..., controller_id: _Optional[str] = ..., session_id: _Optional[str] = ..., wire_version: _Optional[int] = ..., n_axes: _Optional[int] = ..., cycle_period_ns: _Optional[int] = ..., clock_hz: _Optional[int] = ..., ring_capacity: _Optional[int] = ..., realtime_ns: _Optional[int] = ...) -> None: ...

class CanFrame(_message.Message):
    __slots__ = ("bus", "t_bus_ns", "id", "extended", "remote", "dlc", "data", "bits", "from_servo", "error")
    BUS_FIELD_NUMBER: _ClassVar[int]
    T_BUS_NS_FIELD_NUMBER: _ClassVar[int]
    ID_FIELD_NUMBER: _ClassVar[int]
    EXTENDED_FIELD_NUMBER: _ClassVar[int]
    REMOTE_FIELD_NUMBER: _ClassVar[int]
    DLC_FIELD_NUMBER: _ClassVar[int]
    DATA_FIELD_NUMBER: _ClassVar[int]
    BITS_FIELD_NUMBER: _ClassVar[int]
    FROM_SERVO_FIELD_NUMBER: _ClassVar[int]
    ERROR_FIELD_NUMBER: _ClassVar[int]
    bus: int
    t_bus_ns: int
    id: int
    extended: bool
    remote: bool
    dlc: int
    data: bytes
    bits: int
    from_servo: bool
    error: bool
    def __init__(self, bus: _Optional[int] = ..., t_bus_ns: _Optional[int] = ..., id: _Optional[int] = ..., extended: _Optional[bool] = ..., remote: _Optional[bool] = ..., dlc: _Optional[int] = ..., data: _Optional[bytes] = ..., bits: _Optional[int] = ..., from_servo: _Optional[bool] = ..., error: _Optional[bool] = ...) -> None: ...
