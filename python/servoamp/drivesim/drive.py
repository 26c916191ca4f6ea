# SPDX-License-Identifier: MIT
"""One simulated CiA 402 drive: CANopen slave (NMT, SDO server, SYNC
consumer, PDOs, heartbeat producer and consumer, node and life guarding,
EMCY), the 402 state machine in cyclic synchronous position mode, and a
motor-and-load model. Any frame a master can send is answered as CiA 301
has it (an SDO abort for a bad request or PDO mapping), never with an
exception.

Deterministic: the drive has no clock of its own. Every call of
:meth:`Drive.on_frame` carries the guest time of the frame (its end on the
modelled bus); heartbeats, the model, timeouts and injected faults all run
on those times. The object dictionary and the SDO server are canopen's
(LocalNode from the EDS), with their host-timer services (the heartbeat
thread) left out.
"""

from __future__ import annotations

import enum
import logging
import math
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import canopen
from canopen.objectdictionary import NUMBER_TYPES, ODVariable
from canopen.sdo.server import SdoServer
from canopen.sdo.constants import EXPEDITED, NO_MORE_DATA
from canopen.sdo.exceptions import SdoAbortedError

from servoamp.drivesim import cia402
from servoamp.drivesim.cia402 import State
from servoamp.drivesim.model import Motor

log = logging.getLogger("servoamp.drivesim")

EDS = Path(__file__).with_name("servoamp_csp_drive.eds")

MODE_CSP = 8
SUPPORTED_MODES = (0, MODE_CSP)

# EMCY error codes (CiA 301 / 402)
ERR_RESET = 0x0000
ERR_OVER_CURRENT = 0x2310          # continuous over-current, device output side
ERR_FOLLOWING = 0x8611             # position control: following error
ERR_PDO_LENGTH = 0x8210            # PDO not processed: length error
ERR_GUARDING = 0x8130              # life guard error or heartbeat error

ERRREG_GENERIC = 0x01
ERRREG_CURRENT = 0x02
ERRREG_COMMUNICATION = 0x10
ERRREG_PROFILE = 0x20

# SDO abort codes (CiA 301)
ABORT_COMMAND = 0x05040001         # client/server command specifier not valid or unknown
ABORT_OUT_OF_MEMORY = 0x05040005
ABORT_NO_OBJECT = 0x06020000       # object does not exist in the object dictionary
ABORT_NOT_MAPPABLE = 0x06040041    # object cannot be mapped to the PDO
ABORT_PDO_LENGTH = 0x06040042      # number and length of the objects to be mapped exceed the PDO length
ABORT_NO_SUBINDEX = 0x06090011
ABORT_VALUE_RANGE = 0x06090030
ABORT_GENERAL = 0x08000000

SDO_SEGMENTED_MAX = 4096           # bytes a segmented download may carry
PDO_BITS_MAX = 64


class Nmt(enum.IntEnum):
    """NMT states as the heartbeat reports them."""
    INITIALISING = 0x00
    STOPPED = 0x04
    OPERATIONAL = 0x05
    PRE_OPERATIONAL = 0x7F


class FaultKind(enum.Enum):
    FOLLOWING_ERROR = "following-error"
    OVER_CURRENT = "over-current"
    OFF_BUS = "off-bus"


FAULT_ALIASES = {
    "following-error": FaultKind.FOLLOWING_ERROR, "fe": FaultKind.FOLLOWING_ERROR,
    "jam": FaultKind.FOLLOWING_ERROR,
    "over-current": FaultKind.OVER_CURRENT, "overcurrent": FaultKind.OVER_CURRENT,
    "oc": FaultKind.OVER_CURRENT,
    "off-bus": FaultKind.OFF_BUS, "off": FaultKind.OFF_BUS, "drop": FaultKind.OFF_BUS,
}


@dataclass(frozen=True)
class Injection:
    """A fault injected into drive ``node`` at guest time ``t_ns``."""
    node: int
    kind: FaultKind
    t_ns: int

    @classmethod
    def parse(cls, text: str) -> Injection:
        """``NODE:KIND@T_S``, e.g. ``2:following-error@0.5``."""
        try:
            node_s, rest = text.split(":", 1)
            kind_s, t_s = rest.split("@", 1)
            node = int(node_s, 0)
            t = float(t_s)
        except ValueError:
            raise ValueError(f"fault {text!r}: want NODE:KIND@T_S") from None
        kind = FAULT_ALIASES.get(kind_s.strip().lower())
        if kind is None:
            raise ValueError(f"fault {text!r}: kind is one of "
                             + ", ".join(k.value for k in FaultKind))
        if not 1 <= node <= 127 or not t >= 0:
            raise ValueError(f"fault {text!r}: node 1..127, time >= 0")
        return cls(node, kind, round(t * 1e9))


@dataclass(frozen=True)
class Frame:
    """A frame the drive puts on the bus; ``t_ns`` the earliest guest time
    it may start (0: as soon as possible)."""
    can_id: int
    data: bytes
    t_ns: int = 0


class _Outbox(canopen.Network):
    """canopen's Network as the SDO server's sender: it keeps the frames."""

    def __init__(self) -> None:
        super().__init__()
        self.frames: list[Frame] = []

    def send_message(self, can_id: int, data: bytes | bytearray, remote: bool = False) -> None:
        self.frames.append(Frame(can_id, bytes(data)))


class _SdoServer(SdoServer):
    """canopen's SDO server, with every request a master can send answered
    as CiA 301 has it: a segment outside a transfer of its kind, block
    transfers (not supported) and command specifier 7 are aborted with
    0x05040001, a segmented download stops at SDO_SEGMENTED_MAX bytes
    (0x05040005), and anything else that goes wrong is an abort too
    (0x08000000), never an exception out of :meth:`on_request`. The
    abort names the request's multiplexer (an initiate's or an unknown
    command's bytes 1-3; a segment's transfer's)."""

    def __init__(self, node: canopen.LocalNode, node_id: int) -> None:
        super().__init__(0x600 + node_id, 0x580 + node_id, node)  # type: ignore[no-untyped-call]
        self._node_id = node_id
        self._index = 0
        self._subindex = 0
        self._transfer: str | None = None      # "upload" | "download": a segmented one going on

    def on_request(self, can_id: int, data: bytearray, timestamp: float) -> None:
        ccs = data[0] >> 5
        if ccs == 4:                           # the client aborts: no answer
            self._transfer = None
            return
        segment = {0: "download", 3: "upload"}.get(ccs)
        if segment is None:                    # an initiate (or not a command): its multiplexer
            self._index, self._subindex = struct.unpack_from("<HB", data, 1)
            self._transfer = None
        if ccs >= 5 or (segment is not None and self._transfer != segment):
            self._abort(ABORT_COMMAND)
            return
        if ccs == 0 and len(self._buffer or b"") + 7 > SDO_SEGMENTED_MAX:
            self._abort(ABORT_OUT_OF_MEMORY)
            return
        try:
            if ccs == 1:
                self.init_download(data)  # type: ignore[no-untyped-call]
                self._transfer = None if data[0] & EXPEDITED else "download"
            elif ccs == 2:
                self._buffer = None
                self.init_upload(data)  # type: ignore[no-untyped-call]
                self._transfer = "upload" if self._buffer else None
            elif ccs == 0:
                self._transfer = None if data[0] & NO_MORE_DATA else "download"
                self.segmented_download(data[0], data)  # type: ignore[no-untyped-call]
            else:
                self.segmented_upload(data[0])  # type: ignore[no-untyped-call]
                self._transfer = "upload" if self._buffer else None
        except SdoAbortedError as exc:
            self._abort(exc.code)
        except KeyError:
            self._abort(ABORT_NO_OBJECT)
        except Exception as exc:               # canopen's own: still an answer, and the drive goes on
            log.info("node %d: SDO request %s failed: %r", self._node_id, bytes(data).hex(), exc)
            self._abort(ABORT_GENERAL)

    def abort(self, abort_code: int = ABORT_GENERAL) -> None:
        self._abort(abort_code)

    def _abort(self, code: int) -> None:
        self._transfer = None
        self.send_response(struct.pack("<BHBL", 0x80, self._index, self._subindex, code))  # type: ignore[no-untyped-call]


def _int(od: ODVariable, data: bytes) -> int:
    value = od.decode_raw(data)
    if not isinstance(value, int):
        raise SdoAbortedError(0x06070010)      # data type does not match
    return value


def _clamped(x: float, bits: int) -> int:
    lo, hi = -(1 << (bits - 1)), (1 << (bits - 1)) - 1
    if math.isnan(x):
        return 0
    if math.isinf(x):
        return hi if x > 0 else lo
    return max(lo, min(hi, int(round(x))))


def _i32(x: float) -> int:
    return _clamped(x, 32)


def _i16(x: float) -> int:
    return _clamped(x, 16)


@dataclass(frozen=True)
class _Pdo:
    cob_id: int
    trans_type: int
    mapping: tuple[tuple[int, int, int], ...]   # (index, subindex, bits)
    rtr: bool = True                            # a remote frame asks for it (COB-ID bit 30 clear)

    @property
    def length(self) -> int:
        return sum(bits for _, _, bits in self.mapping) // 8


def parse_reset_cycles(text: str) -> tuple[int | None, int | None]:
    """``[NODE:]CYCLES`` or ``[NODE:]never`` (--fault-reset-cycles): the node
    (None: every drive) and the SYNCs a fault reset takes (None: never)."""
    node_s, _, value = text.rpartition(":")
    try:
        node = int(node_s, 0) if node_s else None
        cycles = None if value.strip().lower() == "never" else int(value, 0)
    except ValueError:
        raise ValueError(f"fault reset {text!r}: want [NODE:]CYCLES or [NODE:]never") from None
    if (node is not None and not 1 <= node <= 127) or (cycles is not None and not 0 <= cycles <= 100_000):
        raise ValueError(f"fault reset {text!r}: node 1..127, cycles 0..100000 or never")
    return node, cycles


class Drive:
    """A CiA 402 drive with CANopen node id ``node_id``.

    ``fault_reset_cycles``: how many SYNCs the drive needs to leave Fault
    after the rising edge of the controlword's fault reset bit (7), with the
    bit held all along (a word without it abandons the reset, as a drive
    that samples the bit when its reset completes does); 0 (default): at
    the edge, as the standard's transition 15; None: never (a fault that
    does not clear)."""

    def __init__(self, node_id: int, eds: Path | str = EDS,
                 faults: tuple[Injection, ...] | list[Injection] = (),
                 fault_reset_cycles: int | None = 0) -> None:
        if not 1 <= node_id <= 127:
            raise ValueError(f"node id {node_id} not in 1..127")
        self.node_id = node_id
        self.fault_reset_cycles = fault_reset_cycles
        self.reset_left: int | None = None     # SYNCs left of a running fault reset (-1: never ends)
        self.eds = str(eds)
        self.injections = sorted((f for f in faults if f.node == node_id), key=lambda f: f.t_ns)
        self.motor = Motor()
        self.t_ns = 0
        self.nmt = Nmt.INITIALISING
        self.off_bus = False
        self._outbox = _Outbox()
        self._emcy_pending: list[tuple[int, int]] = []
        self.node = self._new_node()
        self._reset_application_state()

    # --- object dictionary ------------------------------------------------

    def _new_node(self) -> canopen.LocalNode:
        od = canopen.import_od(self.eds, self.node_id)
        node = canopen.LocalNode(self.node_id, od)
        node.sdo = _SdoServer(node, self.node_id)
        # canopen's NMT slave starts a host-timer heartbeat on writes of
        # 0x1017: the heartbeat here runs on guest time instead.
        node._write_callbacks.remove(node.nmt.on_write)
        node.add_read_callback(self._on_read)  # type: ignore[no-untyped-call]
        node.add_write_callback(self._on_write)  # type: ignore[no-untyped-call]
        self._outbox = _Outbox()
        node.associate_network(self._outbox)
        return node

    def _reset_application_state(self) -> None:
        self.state = State.NOT_READY
        self.reset_left = None
        self.controlword = 0
        self.mode = 0
        self.error_code = 0
        self.error_register = 0                # of the 402 fault; 0x1001 adds the communication errors
        self.reaction_syncs = 0                # SYNCs seen in Fault reaction active
        self.error_history: list[int] = []     # 0x1003, the newest first
        self.demand = self.motor.pos
        self.demand_prev = self.motor.pos
        self.hold = self.motor.pos
        self.fe_time_s = 0.0
        self.last_sync_ns: int | None = None
        self.rpdo_latched: dict[int, bytes] = {}
        self.sync_count = 0
        self.hb_next_ns: int | None = None
        self._reset_communication_state()
        self._load_model_parameters()

    def _reset_communication_state(self) -> None:
        self._pdo_cache: tuple[list[_Pdo], list[_Pdo]] | None = None
        self.rpdo_latched = {}
        self.comm_errors: set[str] = set()     # "pdo-length", "guarding", "heartbeat N"
        self.guard_toggle = 0
        self.guard_seen_ns: int | None = None  # the last node guarding request
        self.hb_seen: dict[int, int] = {}      # consumed heartbeats: node -> guest time last seen
        self.tpdo_sent: dict[int, bytes] = {}  # COB-ID -> the data last sent
        self.tpdo_sampled: dict[int, bytes] = {}   # transmission type 252: sampled at SYNC

    def _load_model_parameters(self) -> None:
        self.motor.bandwidth_hz = float(self.read(0x2000, 1))
        self.motor.damping = self.read(0x2000, 2) / 1000.0
        self.motor.accel_rated = float(self.read(0x2000, 3))
        self.motor.max_current_pm = float(self.read(0x6073, 0))

    def _var(self, index: int, subindex: int) -> ODVariable:
        obj = self.node.object_dictionary[index]
        if isinstance(obj, ODVariable):
            return obj
        var = obj[subindex]
        assert isinstance(var, ODVariable)
        return var

    def read(self, index: int, subindex: int = 0) -> Any:
        """The value of an object as the SDO server would give it."""
        return self._var(index, subindex).decode_raw(self.node.get_data(index, subindex))

    def write(self, index: int, subindex: int, value: Any) -> None:
        """Write an object as an SDO download would (callbacks included)."""
        self.node.set_data(index, subindex, self._var(index, subindex).encode_raw(value))

    def statusword(self) -> int:
        sw = cia402.STATE_BITS[self.state] | cia402.SW_REMOTE
        if self.state in (State.READY_TO_SWITCH_ON, State.SWITCHED_ON) or cia402.powered(self.state):
            sw |= cia402.SW_VOLTAGE_ENABLED
        if self.state == State.OPERATION_ENABLED and self.mode == MODE_CSP:
            sw |= cia402.SW_CSP_FOLLOWING
            if self.fe_time_s > 0:
                sw |= cia402.SW_FOLLOWING_ERROR
            if abs(self.demand - self.motor.pos) < 1.0 and abs(self.motor.vel) < 1.0:
                sw |= cia402.SW_TARGET_REACHED
        return sw

    def _on_read(self, index: int, subindex: int, od: ODVariable, **_: Any) -> int | None:
        if index == 0x6041:
            return self.statusword()
        if index == 0x6061:
            return self.mode
        if index == 0x6064:
            return _i32(self.motor.pos)
        if index == 0x6062:
            return _i32(self.demand)
        if index == 0x606C:
            return _i32(self.motor.vel)
        if index == 0x6078:
            return _i16(self.motor.current_pm if cia402.powered(self.state) else 0.0)
        if index == 0x60F4:
            return _i32(self.following_error())
        if index == 0x603F:
            return self.error_code
        if index == 0x1001:
            return self.register()
        if index == 0x1003:
            if subindex == 0:
                return len(self.error_history)
            return self.error_history[subindex - 1] if subindex <= len(self.error_history) else 0
        return None

    def register(self) -> int:
        """The error register (0x1001): the fault's bits, and generic plus
        communication while a communication error lasts."""
        comm = ERRREG_GENERIC | ERRREG_COMMUNICATION if self.comm_errors else 0
        return self.error_register | comm

    def _on_write(self, index: int, subindex: int, od: ODVariable, data: bytes, **_: Any) -> None:
        if index == 0x6060:
            mode = _int(od, data)
            if mode not in SUPPORTED_MODES:
                raise SdoAbortedError(0x06090030)      # value range exceeded
            self.mode = mode
        elif index == 0x6040:
            self._apply_controlword(_int(od, data))
        elif index == 0x1017:
            period = _int(od, data)
            self.hb_next_ns = self.t_ns + period * 1_000_000 if period else None
        elif 0x1400 <= index <= 0x1BFF or index == 0x1005:
            if index != 0x1005:
                self._check_pdo_write(index, subindex, od, data)
            self._pdo_cache = None
        elif index == 0x1003:
            if _int(od, data) != 0:
                raise SdoAbortedError(ABORT_VALUE_RANGE)   # only 0: clear the history
            self.error_history = []
        elif index == 0x1016:
            self.hb_seen = {}                  # monitoring starts again with the next heartbeat
            for key in [k for k in self.comm_errors if k.startswith("heartbeat")]:
                self._comm_clear(key)
        elif index == 0x2000 or index == 0x6073:
            value = _int(od, data)
            if index == 0x6073:
                self.motor.max_current_pm = float(value)
            elif subindex == 1:
                self.motor.bandwidth_hz = float(value)
            elif subindex == 2:
                self.motor.damping = value / 1000.0
            elif subindex == 3:
                self.motor.accel_rated = float(value)

    def following_error(self) -> float:
        if self.state == State.OPERATION_ENABLED and self.mode == MODE_CSP:
            return self.demand - self.motor.pos
        return 0.0

    # --- PDO configuration -------------------------------------------------

    def _check_pdo_write(self, index: int, subindex: int, od: ODVariable, data: bytes) -> None:
        """CiA 301 on a write of a PDO's parameters: a transmission type the
        drive has, and a mapping of mappable objects (readable ones into a
        TPDO, writable ones into an RPDO, whole bytes, at most their own
        length) of at most 64 bits; SdoAbortedError otherwise."""
        rx = index < 0x1800
        value = _int(od, data)
        if (index & 0x3FF) < 0x200:            # communication parameter
            if subindex == 2 and not (value <= 240 or value in ((254, 255) if rx else (252, 253, 254, 255))):
                raise SdoAbortedError(ABORT_VALUE_RANGE)
            return
        record = self.node.object_dictionary[index]
        if subindex == 0:
            if isinstance(record, ODVariable) or any(sub not in record for sub in range(1, value + 1)):
                raise SdoAbortedError(ABORT_PDO_LENGTH)    # more entries than the PDO has
            entries = [self.read(index, sub) for sub in range(1, value + 1)]
        else:
            count = self.read(index, 0)
            if subindex > count:
                if value:                      # an entry not in use yet: checked now and with sub 0
                    self._mapped_bits(value, rx)
                return
            entries = [value if sub == subindex else self.read(index, sub) for sub in range(1, count + 1)]
        if sum(self._mapped_bits(e, rx) for e in entries) > PDO_BITS_MAX:
            raise SdoAbortedError(ABORT_PDO_LENGTH)

    def _mapped_bits(self, entry: int, rx: bool) -> int:
        """The bits of a mapping entry (index << 16 | subindex << 8 | bits)
        if the object may be mapped so; SdoAbortedError if not."""
        index, subindex, bits = entry >> 16, (entry >> 8) & 0xFF, entry & 0xFF
        od = self.node.object_dictionary
        if index not in od:
            raise SdoAbortedError(ABORT_NO_OBJECT)
        obj = od[index]
        if not isinstance(obj, ODVariable):
            if subindex not in obj:
                raise SdoAbortedError(ABORT_NO_SUBINDEX)
            obj = obj[subindex]
        elif subindex != 0:
            raise SdoAbortedError(ABORT_NO_SUBINDEX)
        assert isinstance(obj, ODVariable)
        if (not obj.pdo_mappable or not (obj.writable if rx else obj.readable)
                or obj.data_type not in NUMBER_TYPES or bits == 0 or bits % 8 or bits > len(obj)):
            raise SdoAbortedError(ABORT_NOT_MAPPABLE)
        return bits

    def _pdos(self) -> tuple[list[_Pdo], list[_Pdo]]:
        if self._pdo_cache is None:
            self._pdo_cache = (self._pdo_list(0x1400, 0x1600), self._pdo_list(0x1800, 0x1A00))
        return self._pdo_cache

    def _pdo_list(self, comm: int, mapping: int) -> list[_Pdo]:
        od = self.node.object_dictionary
        pdos = []
        for i in range(512):
            if comm + i not in od or mapping + i not in od:
                if i >= 4:
                    break
                continue
            try:
                cob = self.read(comm + i, 1)
                if cob & 0x80000000:
                    continue        # not valid
                entries = []
                for sub in range(1, self.read(mapping + i, 0) + 1):
                    m = self.read(mapping + i, sub)
                    self._mapped_bits(m, comm == 0x1400)
                    entries.append((m >> 16, (m >> 8) & 0xFF, m & 0xFF))
                pdo = _Pdo(cob & 0x7FF, self.read(comm + i, 2), tuple(entries), not cob & 0x40000000)
            except (SdoAbortedError, KeyError) as exc:  # writes are checked: an EDS's own mistake
                log.info("node %d: PDO %#06x left out: %r", self.node_id, mapping + i, exc)
                continue
            if pdo.length <= 8:
                pdos.append(pdo)
        return pdos

    def _tpdo_data(self, pdo: _Pdo) -> bytes:
        return b"".join(self.node.get_data(i, s)[: bits // 8] for i, s, bits in pdo.mapping)

    def _tpdo(self, pdo: _Pdo, data: bytes | None = None) -> Frame:
        """TPDO ``pdo`` as sent now (``data``: sampled before)."""
        if data is None:
            data = self._tpdo_data(pdo)
        self.tpdo_sent[pdo.cob_id] = data
        return Frame(pdo.cob_id, data)

    def _tpdo_events(self) -> list[Frame]:
        """Transmission types 254/255: a TPDO whose data changed (the
        drive's events are the changes of what it maps), checked after
        every frame in Operational."""
        out = []
        if self.nmt == Nmt.OPERATIONAL:
            for pdo in self._pdos()[1]:
                if pdo.trans_type >= 254:
                    data = self._tpdo_data(pdo)
                    if data != self.tpdo_sent.get(pdo.cob_id):
                        out.append(self._tpdo(pdo, data))
        return out

    # --- state machine -------------------------------------------------------

    def _set_state(self, state: State) -> None:
        if state != self.state:
            log.info("node %d: %s -> %s at %.6f s", self.node_id, cia402.NAMES[self.state],
                     cia402.NAMES[state], self.t_ns / 1e9)
            if state == State.QUICK_STOP_ACTIVE or state == State.FAULT_REACTION_ACTIVE:
                self.hold = self.motor.pos
            if state == State.OPERATION_ENABLED:
                self.fe_time_s = 0.0
            self.state = state

    def _apply_controlword(self, cw: int) -> None:
        prev, self.controlword = self.controlword, cw
        edge = bool(cw & cia402.CW_FAULT_RESET and not prev & cia402.CW_FAULT_RESET)
        if edge and "pdo-length" in self.comm_errors:
            # a fault reset acknowledges a PDO length error too
            self.comm_errors.discard("pdo-length")
            if self.state != State.FAULT or self.fault_reset_cycles != 0:
                self._emcy(ERR_RESET)          # else the fault's reset EMCY says it
        if self.state == State.FAULT and self.fault_reset_cycles != 0:
            if edge:
                n = self.fault_reset_cycles
                self.reset_left = -1 if n is None else n
                log.info("node %d: fault reset begun (%s SYNCs) at %.6f s", self.node_id,
                         "never" if n is None else n, self.t_ns / 1e9)
            elif not cw & cia402.CW_FAULT_RESET:
                self.reset_left = None         # bit 7 dropped: the reset is abandoned
            return
        new = cia402.transition(self.state, cw, prev)
        if self.state == State.FAULT and new != State.FAULT:
            self._leave_fault()
        self._set_state(new)

    def _leave_fault(self) -> None:
        self.error_code = 0
        self.error_register = 0
        self.reset_left = None
        self._emcy(ERR_RESET)
        self._set_state(State.SWITCH_ON_DISABLED)

    def _trip(self, code: int, register: int) -> None:
        if self.state in (State.FAULT, State.FAULT_REACTION_ACTIVE):
            return
        log.info("node %d: fault %#06x at %.6f s", self.node_id, code, self.t_ns / 1e9)
        self.error_code = code
        self.error_register = ERRREG_GENERIC | register
        self.reaction_syncs = 0
        self._set_state(State.FAULT_REACTION_ACTIVE)
        self._emcy(code)

    # --- EMCY and the communication errors -------------------------------------

    def _emcy(self, code: int) -> None:
        """An EMCY with ``code`` and the error register as it is now (0:
        an error gone); a code other than 0 goes to 0x1003 too."""
        self._emcy_pending.append((code, self.register()))
        if code != ERR_RESET:
            self.error_history = [code]        # 0x1003 (the EDS's) holds one entry

    def _comm_error(self, key: str, code: int) -> None:
        if key not in self.comm_errors:
            self.comm_errors.add(key)
            self._emcy(code)
        elif key == "pdo-length":
            self._emcy(code)                   # every PDO refused says so

    def _comm_clear(self, key: str) -> None:
        if key in self.comm_errors:
            self.comm_errors.discard(key)
            self._emcy(ERR_RESET)

    def _check_error_control(self) -> None:
        """Life guarding (0x100C x 0x100D ms without a guarding request,
        once guarding began) and the heartbeat consumer (0x1016: a node's
        heartbeat missing for its time, once one came): EMCY 0x8130, gone
        with the next request or heartbeat."""
        if self.guard_seen_ns is not None:
            life_ns = self.read(0x100C) * self.read(0x100D) * 1_000_000
            if life_ns and self.t_ns - self.guard_seen_ns > life_ns:
                self._comm_error("guarding", ERR_GUARDING)
            elif not life_ns:
                self._comm_clear("guarding")
        for n, seen in self.hb_seen.items():
            if self.t_ns - seen > self._consumer_time_ns(n):
                self._comm_error(f"heartbeat {n}", ERR_GUARDING)

    def _consumer_time_ns(self, node: int) -> int:
        """0x1016's time for the heartbeat of ``node`` (0: not consumed)."""
        record = self.node.object_dictionary[0x1016]
        for sub in range(1, self.read(0x1016, 0) + 1):
            if not isinstance(record, ODVariable) and sub in record:
                entry = self.read(0x1016, sub)
                if entry >> 16 & 0xFF == node and entry & 0xFFFF:
                    return int(entry & 0xFFFF) * 1_000_000
        return 0

    def _on_heartbeat(self, node: int) -> None:
        if node != self.node_id and self._consumer_time_ns(node):
            self.hb_seen[node] = self.t_ns
            self._comm_clear(f"heartbeat {node}")

    def _on_remote(self, can_id: int) -> list[Frame]:
        """A remote frame: node guarding (0x700 + node: the NMT state with
        the toggle bit) or a TPDO whose COB-ID allows it."""
        if can_id == 0x700 + self.node_id:
            if self.nmt == Nmt.INITIALISING:
                return []
            answer = Frame(can_id, bytes([self.guard_toggle << 7 | int(self.nmt)]))
            self.guard_toggle ^= 1
            self.guard_seen_ns = self.t_ns
            self._comm_clear("guarding")
            return [answer]
        if self.nmt != Nmt.OPERATIONAL:
            return []
        for pdo in self._pdos()[1]:
            if can_id == pdo.cob_id and pdo.rtr:
                return [self._tpdo(pdo, self.tpdo_sampled.get(pdo.cob_id) if pdo.trans_type == 252 else None)]
        return []

    # --- the bus -------------------------------------------------------------

    def boot(self, t_ns: int) -> list[Frame]:
        """Power on (or the end of an NMT reset) at guest time ``t_ns``: the
        boot-up message, then Pre-operational and Switch on disabled."""
        self.t_ns = max(self.t_ns, t_ns)
        self.nmt = Nmt.PRE_OPERATIONAL
        self._set_state(State.SWITCH_ON_DISABLED)
        period = self.read(0x1017)
        self.hb_next_ns = self.t_ns + period * 1_000_000 if period else None
        return [] if self.off_bus else [Frame(0x700 + self.node_id, b"\x00")]

    def inject(self, kind: FaultKind) -> None:
        """A fault now: applied with the next frame the drive sees (the
        control socket of servoamp-drivesim: tests on a running board)."""
        self.injections.insert(0, Injection(self.node_id, kind, 0))

    def on_frame(self, can_id: int, data: bytes, t_ns: int, rtr: bool = False,
                 eff: bool = False) -> list[Frame]:
        """Handle one frame on the bus at guest time ``t_ns``; the frames the
        drive answers with."""
        self._emcy_pending = []
        self._advance(t_ns)
        if self.off_bus:
            return []
        if eff:
            answers = []
        elif rtr:
            answers = self._on_remote(can_id)
        else:
            answers = self._dispatch(can_id, data)
        if self.state == State.FAULT_REACTION_ACTIVE and self.last_sync_ns is None:
            self._set_state(State.FAULT)           # no SYNC to run the reaction on
        self._check_error_control()
        answers += self._tpdo_events()
        out: list[Frame] = []
        if self.nmt != Nmt.STOPPED:                # EMCY first: the lower COB-ID wins
            for code, reg in self._emcy_pending:
                out.append(Frame(0x80 + self.node_id, struct.pack("<HB5x", code, reg)))
        self._emcy_pending = []
        out += answers
        if self.hb_next_ns is not None and self.t_ns >= self.hb_next_ns:
            out.append(Frame(0x700 + self.node_id, bytes([int(self.nmt)])))
            period = self.read(0x1017) * 1_000_000
            while period and self.hb_next_ns <= self.t_ns:
                self.hb_next_ns += period
        return out

    def _advance(self, t_ns: int) -> None:
        self.t_ns = max(self.t_ns, t_ns)
        while self.injections and self.injections[0].t_ns <= self.t_ns:
            inj = self.injections[0]
            if inj.kind == FaultKind.OFF_BUS:
                log.info("node %d: drops off the bus at %.6f s", self.node_id, self.t_ns / 1e9)
                self.off_bus = True
            elif inj.kind == FaultKind.FOLLOWING_ERROR:
                log.info("node %d: load jams at %.6f s", self.node_id, self.t_ns / 1e9)
                self.motor.jammed = True
            elif inj.kind == FaultKind.OVER_CURRENT:
                if not cia402.powered(self.state):
                    break       # trips once the power stage is on
                self._trip(ERR_OVER_CURRENT, ERRREG_CURRENT)
            self.injections.pop(0)

    def _dispatch(self, can_id: int, data: bytes) -> list[Frame]:
        if can_id == 0x000:
            return self._on_nmt(data)
        if 0x701 <= can_id <= 0x77F and len(data) == 1:
            self._on_heartbeat(can_id - 0x700)
            return []
        if self.nmt == Nmt.STOPPED:
            return []
        sync_id = self.read(0x1005) & 0x7FF
        if can_id == sync_id:
            return self._on_sync() if self.nmt == Nmt.OPERATIONAL else []
        if can_id == 0x600 + self.node_id:
            if len(data) != 8:
                return []       # CiA 301: SDO requests are 8 bytes
            self._outbox.frames = []
            self.node.sdo.on_request(can_id, bytearray(data), self.t_ns / 1e9)  # type: ignore[no-untyped-call]
            return self._outbox.frames
        if self.nmt == Nmt.OPERATIONAL:
            for pdo in self._pdos()[0]:
                if can_id == pdo.cob_id:
                    if len(data) < pdo.length:
                        self._comm_error("pdo-length", ERR_PDO_LENGTH)
                        continue
                    self._comm_clear("pdo-length")
                    if pdo.trans_type >= 254:
                        self._apply_rpdo(pdo, data)
                    else:
                        self.rpdo_latched[pdo.cob_id] = bytes(data)
        return []

    def _on_nmt(self, data: bytes) -> list[Frame]:
        if len(data) != 2 or data[1] not in (0, self.node_id):
            return []
        cs = data[0]
        if cs == 0x01:
            self.nmt = Nmt.OPERATIONAL
        elif cs == 0x02:
            self.nmt = Nmt.STOPPED
        elif cs == 0x80:
            self.nmt = Nmt.PRE_OPERATIONAL
        elif cs == 0x81:                      # reset node: the whole OD
            self.node = self._new_node()
            self._reset_application_state()
            return self.boot(self.t_ns)
        elif cs == 0x82:                      # reset communication: 0x1000-0x1FFF
            for index in [i for i in self.node.data_store if 0x1000 <= i <= 0x1FFF]:
                del self.node.data_store[index]
            self._reset_communication_state()
            return self.boot(self.t_ns)
        return []

    def _apply_rpdo(self, pdo: _Pdo, data: bytes) -> None:
        offset = 0
        for index, subindex, bits in pdo.mapping:
            raw = data[offset: offset + bits // 8]
            offset += bits // 8
            try:
                full = len(self._var(index, subindex)) // 8
                if len(raw) < full:                # a mapping of the low bytes: the rest kept
                    raw += self.node.get_data(index, subindex)[len(raw):full]
                self.node.set_data(index, subindex, raw)
            except (SdoAbortedError, KeyError) as exc:
                log.info("node %d: RPDO write %04x:%02x refused (%s)", self.node_id, index,
                         subindex, exc)

    def _on_sync(self) -> list[Frame]:
        t = self.t_ns
        if self.last_sync_ns is None:
            dt = self.read(0x1006) / 1e6
        else:
            dt = (t - self.last_sync_ns) / 1e9
        self.last_sync_ns = t
        # 1. the interval that ends here, on the setpoint latched at the last SYNC
        if self.state == State.OPERATION_ENABLED and self.mode == MODE_CSP:
            self.motor.step(self.demand_prev, self.demand, dt, True)
        elif cia402.powered(self.state):
            self.motor.step(self.hold, self.hold, dt, True)
        else:
            self.motor.step(0.0, 0.0, dt, False)
        reacting = self.state == State.FAULT_REACTION_ACTIVE
        self._check_following_error(dt)
        if reacting and self.reaction_syncs >= 1:
            self._set_state(State.FAULT)       # the reaction held the motor a whole cycle
        elif self.state == State.FAULT_REACTION_ACTIVE:
            self.reaction_syncs += 1           # tripped in this cycle: its TPDO shows the reaction
        elif self.state == State.FAULT and self.reset_left is not None and self.reset_left > 0:
            self.reset_left -= 1               # a slow fault reset, bit 7 still held
            if self.reset_left == 0:
                self._leave_fault()
        elif (self.state == State.QUICK_STOP_ACTIVE and abs(self.motor.vel) < 1.0
              and self.read(0x605A) in (1, 2, 3, 4)):
            self._set_state(State.SWITCH_ON_DISABLED)
        # 2. latch the RPDOs received since: controlword, target
        rpdos = {p.cob_id: p for p in self._pdos()[0]}
        for cob_id, data in sorted(self.rpdo_latched.items()):
            if cob_id in rpdos:
                self._apply_rpdo(rpdos[cob_id], data)
        self.rpdo_latched = {}
        if self.state == State.OPERATION_ENABLED and self.mode == MODE_CSP:
            self.demand_prev, self.demand = self.demand, float(self.read(0x607A))
        else:
            self.demand_prev = self.demand = self.motor.pos
        # 3. the TPDOs
        self.sync_count += 1
        out = []
        for pdo in self._pdos()[1]:
            if 1 <= pdo.trans_type <= 240 and self.sync_count % pdo.trans_type == 0:
                out.append(self._tpdo(pdo))
            elif pdo.trans_type == 0 and self._tpdo_data(pdo) != self.tpdo_sent.get(pdo.cob_id):
                out.append(self._tpdo(pdo))    # acyclic: at the SYNC after a change
            elif pdo.trans_type == 252:
                self.tpdo_sampled[pdo.cob_id] = self._tpdo_data(pdo)   # for a remote request
        return out

    def _check_following_error(self, dt: float) -> None:
        if self.state != State.OPERATION_ENABLED or self.mode != MODE_CSP:
            self.fe_time_s = 0.0
            return
        window = self.read(0x6065)
        if window == 0xFFFFFFFF or abs(self.following_error()) <= window:
            self.fe_time_s = 0.0
            return
        self.fe_time_s += dt
        if self.fe_time_s * 1000.0 >= self.read(0x6066):
            self._trip(ERR_FOLLOWING, ERRREG_PROFILE)
