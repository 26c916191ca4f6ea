# SPDX-License-Identifier: MIT
"""Client of canlink, the lockstep link between an emulated CAN bus in our
QEMU and host processes (docs/canlink.md), and the exact bus time of a
classic CAN frame.

Every message both ways is one 32-byte little-endian record::

    type u8 | flags u8 | dlc u8 | rsvd u8 | can_id u32 | t_ns u64 | data 8s | seq u32 | rsvd2 u32

A :class:`Link` connects to the Unix socket QEMU listens on, says HELLO
(``active`` for a client that answers frames and holds the guest while it
does; ``listen`` for one held like it that answers nothing and gets only the
frames no client destroyed), and then reads FRAME records (and ERROR, for a
frame destroyed by a bus error); an active client answers a frame with its
own FRAMEs, each carrying that ``seq`` (so QEMU charges them to that frame
and no other), and ends it with DONE(seq), a listener with DONE alone; a
FRAME with ``seq`` 0 is a frame outside an exchange. Every record read is checked
(:func:`unpack`): an unknown type, a dlc over 8, an identifier over its range
or nonzero reserved fields raise :class:`ProtocolError`.

:func:`frame_bits` is the length on the wire of a classic CAN data or remote
frame, with ISO 11898-1 bit stuffing, as QEMU's backend models it.
"""

from __future__ import annotations

import re
import select
import socket
import struct
import threading
import time
from dataclasses import dataclass

HELLO = 1
FRAME = 2
DONE = 3
BYE = 4
ERROR = 5
TYPES = (HELLO, FRAME, DONE, BYE, ERROR)

FLAG_EFF = 0x01
FLAG_RTR = 0x02
FLAG_INFO = 0x80
FRAME_FLAGS = FLAG_EFF | FLAG_RTR | FLAG_INFO
HELLO_ACTIVE = 0x01
HELLO_LISTEN = 0x02        # held, sends nothing, sees only frames not destroyed
DONE_ERROR = 0x01          # DONE: this client destroyed the frame (a bus error)
# bus time a destroyed frame adds past its own end: error flag (6), error
# delimiter (8), intermission (3), less the 3 intermission bits it had
ERROR_BITS = 14

SFF_MAX = 0x7FF
EFF_MAX = 0x1FFFFFFF

RECORD = struct.Struct("<BBBBIQ8sII")
assert RECORD.size == 32
RECORD_SIZE = RECORD.size


class ProtocolError(Exception):
    """A record that breaks docs/canlink.md, or a peer that went away in the
    middle of one."""


@dataclass(frozen=True)
class Record:
    """One canlink message. ``data`` holds exactly ``dlc`` bytes for a data
    FRAME (none for a remote frame); for HELLO it is the name."""

    type: int
    flags: int = 0
    dlc: int = 0
    can_id: int = 0
    t_ns: int = 0
    data: bytes = b""
    seq: int = 0

    @property
    def eff(self) -> bool:
        return bool(self.flags & FLAG_EFF)

    @property
    def rtr(self) -> bool:
        return bool(self.flags & FLAG_RTR)

    @property
    def info(self) -> bool:
        return bool(self.flags & FLAG_INFO)

    @property
    def destroyed(self) -> bool:
        """DONE from a client: it destroyed the frame (a bus error)."""
        return self.type == DONE and bool(self.flags & DONE_ERROR)

    @property
    def active(self) -> bool:
        """HELLO from a client: it answers frames (holds the guest)."""
        return self.type == HELLO and bool(self.flags & HELLO_ACTIVE)

    @property
    def listen(self) -> bool:
        """HELLO from a client: a listener (holds the guest, answers
        nothing, gets only the frames that were not destroyed)."""
        return self.type == HELLO and bool(self.flags & HELLO_LISTEN)


def _check(rec: Record) -> None:
    if rec.type not in TYPES:
        raise ProtocolError(f"unknown record type {rec.type}")
    if not 0 <= rec.flags <= 0xFF:
        raise ProtocolError(f"flags {rec.flags} out of range")
    if not 0 <= rec.t_ns < 1 << 64:
        raise ProtocolError(f"t_ns {rec.t_ns} out of range")
    if not 0 <= rec.seq < 1 << 32:
        raise ProtocolError(f"seq {rec.seq} out of range")
    if rec.type in (FRAME, ERROR):
        if rec.flags & ~(FRAME_FLAGS if rec.type == FRAME else FLAG_EFF | FLAG_RTR):
            raise ProtocolError(f"unknown {'FRAME' if rec.type == FRAME else 'ERROR'} flags {rec.flags:#x}")
        if not 0 <= rec.dlc <= 8:
            raise ProtocolError(f"dlc {rec.dlc} over 8")
        limit = EFF_MAX if rec.eff else SFF_MAX
        if not 0 <= rec.can_id <= limit:
            raise ProtocolError(f"can_id {rec.can_id:#x} over {limit:#x}")
        want = 0 if rec.rtr else rec.dlc
        if len(rec.data) != want:
            raise ProtocolError(f"{len(rec.data)} data bytes for dlc {rec.dlc}"
                                f"{' (remote frame)' if rec.rtr else ''}")
    else:
        if rec.type == DONE and rec.flags & ~DONE_ERROR:
            raise ProtocolError(f"unknown DONE flags {rec.flags:#x}")
        if rec.dlc != 0 and rec.type != HELLO:
            raise ProtocolError(f"dlc {rec.dlc} in a non-FRAME record")
        if not 0 <= rec.can_id < 1 << 32:
            raise ProtocolError(f"can_id {rec.can_id} out of range")
        if len(rec.data) > 8:
            raise ProtocolError("more than 8 data bytes")


def pack(rec: Record) -> bytes:
    """The 32 bytes of ``rec``; :class:`ProtocolError` if it is not valid."""
    _check(rec)
    return RECORD.pack(rec.type, rec.flags, rec.dlc, 0, rec.can_id, rec.t_ns,
                       rec.data.ljust(8, b"\0"), rec.seq, 0)


def unpack(buf: bytes) -> Record:
    """The record in 32 bytes, bounds-checked: :class:`ProtocolError` for a
    wrong length, an unknown type, a dlc over 8, an identifier over its
    range, nonzero reserved fields, or payload bytes past the dlc."""
    if len(buf) != RECORD_SIZE:
        raise ProtocolError(f"record of {len(buf)} bytes, not {RECORD_SIZE}")
    typ, flags, dlc, rsvd, can_id, t_ns, data, seq, rsvd2 = RECORD.unpack(buf)
    if rsvd != 0 or rsvd2 != 0:
        raise ProtocolError("nonzero reserved field")
    if typ in (FRAME, ERROR):
        if dlc > 8:
            raise ProtocolError(f"dlc {dlc} over 8")
        used = 0 if flags & FLAG_RTR else dlc
        if any(data[used:]):
            raise ProtocolError("payload bytes past the dlc")
        payload = bytes(data[:used])
    elif typ == HELLO:
        payload = bytes(data).rstrip(b"\0")
    else:
        payload = b""
    rec = Record(typ, flags, dlc, can_id, t_ns, payload, seq)
    _check(rec)
    return rec


# --- bus time ---------------------------------------------------------------

CRC15_POLY = 0x4599
# CRC delimiter, ACK slot, ACK delimiter, 7 bits EOF, 3 bits intermission
TRAILER_BITS = 13


def _bits(value: int, width: int) -> list[int]:
    return [(value >> (width - 1 - i)) & 1 for i in range(width)]


def _crc15(bits: list[int]) -> int:
    crc = 0
    for b in bits:
        nxt = b ^ (crc >> 14)
        crc = (crc << 1) & 0x7FFF
        if nxt:
            crc ^= CRC15_POLY
    return crc


def _frame_payload(can_id: int, eff: bool, rtr: bool, dlc: int, data: bytes) -> bytes:
    """The data bits' bytes of a frame (none for a remote frame), its
    fields checked: ValueError for a dlc over 8, an id over its range, or
    data that is not dlc bytes."""
    if not 0 <= dlc <= 8:
        raise ValueError(f"dlc {dlc} over 8")
    if not 0 <= can_id <= (EFF_MAX if eff else SFF_MAX):
        raise ValueError(f"can_id {can_id:#x} out of range")
    payload = b"" if rtr else bytes(data)
    if len(payload) != (0 if rtr else dlc):
        raise ValueError(f"{len(payload)} data bytes for dlc {dlc}")
    return payload


def frame_bitstream(can_id: int, eff: bool, rtr: bool, dlc: int, data: bytes) -> list[int]:
    """The unstuffed bits from SOF to the last CRC bit (0 dominant)."""
    payload = _frame_payload(can_id, eff, rtr, dlc, data)
    bits = [0]                                           # SOF
    if eff:
        bits += _bits(can_id >> 18, 11) + [1, 1]         # base id, SRR, IDE
        bits += _bits(can_id & 0x3FFFF, 18) + [int(rtr), 0, 0]  # ext id, RTR, r1, r0
    else:
        bits += _bits(can_id, 11) + [int(rtr), 0, 0]     # id, RTR, IDE, r0
    bits += _bits(dlc, 4)
    for byte in payload:
        bits += _bits(byte, 8)
    return bits + _bits(_crc15(bits), 15)


def stuff_count(bits: list[int]) -> int:
    """Stuff bits ISO 11898-1 inserts into ``bits``: one after every five
    equal bits, the stuff bit itself starting the next run."""
    count = 0
    run = 0
    last = -1
    for b in bits:
        if b == last:
            run += 1
        else:
            last, run = b, 1
        if run == 5:
            count += 1
            last, run = 1 - b, 1
    return count


def _crc15_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte << 7
        for _ in range(8):
            crc = ((crc << 1) ^ CRC15_POLY) if crc & 0x4000 else crc << 1
        table.append(crc & 0x7FFF)
    return tuple(table)


_CRC15_TABLE = _crc15_table()
_RUNS = re.compile(r"0+|1+")


def frame_bits(can_id: int, eff: bool, rtr: bool, dlc: int, data: bytes) -> int:
    """Exact length in bits of a classic CAN data or remote frame on the
    wire: SOF to the last CRC bit with its stuff bits, plus the 13
    unstuffed bits from the CRC delimiter to the end of intermission.

    The same count as ``frame_bitstream`` + ``stuff_count`` (the reference,
    bit by bit; a test compares them), about ten times faster: the bridge
    computes it for every frame it records. The bitstream is one integer,
    the CRC goes a byte at a time after the stream's odd first bits, and the
    stuff bits come from the runs of equal bits: a run of length L that
    follows a stuff bit of its own value counts L + 1; every 5 of that
    take one stuff bit, and a stuff bit right at the run's end joins the
    next run."""
    payload = _frame_payload(can_id, eff, rtr, dlc, data)
    if eff:     # SOF, base id, SRR, IDE, ext id, RTR, r1, r0, DLC: 39 bits
        head = ((((can_id >> 18) << 2 | 3) << 18 | (can_id & 0x3FFFF)) << 3 | int(rtr) << 2) << 4 | dlc
        n = 39
    else:       # SOF, id, RTR, IDE, r0, DLC: 19 bits
        head = ((can_id << 3) | int(rtr) << 2) << 4 | dlc
        n = 19
    body = head << 8 * len(payload) | int.from_bytes(payload, "big")
    nbody = n + 8 * len(payload)
    crc = 0
    for i in range(nbody - 1, nbody - 1 - nbody % 8, -1):      # the odd bits first
        if (body >> i & 1) ^ (crc >> 14):
            crc = ((crc << 1) ^ CRC15_POLY) & 0x7FFF
        else:
            crc = (crc << 1) & 0x7FFF
    for byte in (body & ((1 << (nbody - nbody % 8)) - 1)).to_bytes(nbody // 8, "big"):
        crc = ((crc << 8) & 0x7FFF) ^ _CRC15_TABLE[((crc >> 7) ^ byte) & 0xFF]
    value = body << 15 | crc
    length = nbody + 15
    stuff = carry = 0
    for run in _RUNS.findall(format(value, f"0{length}b")):
        e = len(run) + carry
        stuff += e // 5
        carry = 1 if e % 5 == 0 else 0
    return length + stuff + TRAILER_BITS


def arbitration_key(can_id: int, eff: bool, rtr: bool) -> int:
    """The arbitration field as a number, as canlink orders the frames that
    contend for the bus (docs/canlink.md, "Arbitration"): of two frames
    starting together the one with the lower key wins, as on the wire the
    first bit they differ in is dominant (0) for the winner. Standard:
    11-bit id, RTR, IDE 0; extended: base id, SRR 1, IDE 1, 18-bit
    extension, RTR. So the lower base id first; with the same base id a
    standard data frame, then a standard remote frame, then the extended
    ones (data before remote). The same bits as ``frame_bitstream`` from
    the first id bit to the last bit of the arbitration field (a test
    compares them)."""
    if not 0 <= can_id <= (EFF_MAX if eff else SFF_MAX):
        raise ValueError(f"can_id {can_id:#x} out of range")
    if eff:
        return (can_id >> 18) << 21 | 1 << 20 | 1 << 19 | (can_id & 0x3FFFF) << 1 | int(rtr)
    return can_id << 21 | int(rtr) << 20


# --- the client ---------------------------------------------------------------


class Link:
    """A connection to QEMU's canlink backend.

    ``connect`` sends HELLO and waits for QEMU's (bit rate, guest time).
    :meth:`recv` returns the next FRAME or BYE record (``None`` on timeout;
    :class:`ProtocolError` when QEMU closed the socket). :meth:`send_frame`
    and :meth:`done` may be called from another thread than :meth:`recv`.

    An active client's frames sent after :meth:`recv` returned a guest frame
    (a FRAME that is not INFO) and before its :meth:`done` are that frame's
    answers: they carry its ``seq``. Frames sent at any other time (after an
    INFO frame: an answer to another client's frame; from another thread
    between exchanges) carry ``seq`` 0: frames outside an exchange, which
    QEMU queues for the bus as it reads them and never charges to a guest
    frame (docs/canlink.md, "The exchange").
    """

    def __init__(self, sock: socket.socket, active: bool, listen: bool = False) -> None:
        self.sock = sock
        self.active = active or listen      # owes a DONE for every guest frame
        self.listen = listen
        self.bitrate = 0
        self.t_hello_ns = 0
        self.closed = False
        self._buf = bytearray()
        self._pending: list[Record] = []
        self._wlock = threading.Lock()
        self._answering = 0     # seq of the guest frame being answered, 0: none

    @classmethod
    def connect(cls, path: str, active: bool = False, name: str = "",
                timeout: float = 10.0, listen: bool = False) -> Link:
        """Connect to ``path``, say HELLO, and read QEMU's HELLO (at most
        ``timeout`` seconds). FRAMEs and ERRORs that arrive before it are kept for
        :meth:`recv`."""
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            sock.settimeout(timeout)
            sock.connect(path)
            sock.settimeout(None)
            link = cls(sock, active, listen)
            link._send(Record(HELLO, (HELLO_ACTIVE if active or listen else 0) | (HELLO_LISTEN if listen else 0),
                              data=name.encode("ascii", "replace")[:8]))
            deadline = time.monotonic() + timeout
            while True:
                rec = link._read(max(0.0, deadline - time.monotonic()))
                if rec is None:
                    raise ProtocolError(f"{path}: no HELLO from QEMU in {timeout} s")
                if rec.type == HELLO:
                    link.bitrate = rec.can_id
                    link.t_hello_ns = rec.t_ns
                    if link.bitrate <= 0:
                        raise ProtocolError("QEMU's HELLO has bit rate 0")
                    return link
                if rec.type == BYE:
                    raise ProtocolError(f"{path}: BYE before HELLO")
                if rec.type in (FRAME, ERROR):
                    link._pending.append(rec)
        except BaseException:
            sock.close()
            raise

    def fileno(self) -> int:
        return self.sock.fileno()

    def _send(self, rec: Record) -> None:
        raw = pack(rec)
        with self._wlock:
            self.sock.sendall(raw)

    def _read(self, timeout: float | None) -> Record | None:
        """One record; None when ``timeout`` passed first."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while len(self._buf) < RECORD_SIZE:
            if deadline is not None:
                left = deadline - time.monotonic()
                if left <= 0 and not select.select([self.sock], [], [], 0)[0]:
                    return None
                if left > 0 and not select.select([self.sock], [], [], left)[0]:
                    return None
            chunk = self.sock.recv(4096)
            if not chunk:
                self.closed = True
                if self._buf:
                    raise ProtocolError(f"connection closed inside a record ({len(self._buf)} bytes)")
                raise ProtocolError("connection closed by QEMU")
            self._buf += chunk
        raw = bytes(self._buf[:RECORD_SIZE])
        del self._buf[:RECORD_SIZE]
        return unpack(raw)

    def recv(self, timeout: float | None = None) -> Record | None:
        """The next FRAME, ERROR (a frame destroyed by a bus error: its
        ``seq``, and ``t_ns`` = the end of the error frame) or BYE from QEMU
        (a DONE or HELLO is a protocol error); None if ``timeout`` seconds
        passed first."""
        rec = self._pending.pop(0) if self._pending else self._read(timeout)
        if rec is not None and rec.type not in (FRAME, BYE, ERROR):
            raise ProtocolError(f"unexpected record type {rec.type} from QEMU")
        if rec is not None and rec.type == BYE:
            self.closed = True
        if rec is not None:
            # frames sent from now on answer this record: a guest frame
            # (its seq), or an INFO frame or ERROR (frames outside an exchange)
            self._answering = rec.seq if rec.type == FRAME and not rec.info and self.active else 0
        return rec

    def send_frame(self, can_id: int, data: bytes = b"", eff: bool = False,
                   rtr: bool = False, dlc: int | None = None, t_ns: int = 0,
                   seq: int | None = None) -> None:
        """Put a frame on the bus: as an answer to the guest frame being
        handled (active client, between :meth:`recv` returning it and its
        :meth:`done`: ``seq`` defaults to that frame's) or as a frame outside
        an exchange (``seq`` 0, the default at any other time). ``t_ns`` is
        the earliest guest time it may start (0: none). A listener may not
        send (QEMU would close the link)."""
        if self.listen:
            raise ProtocolError("a listener sends no frames")
        n = len(data) if dlc is None else dlc
        self._send(Record(FRAME, (FLAG_EFF if eff else 0) | (FLAG_RTR if rtr else 0),
                          n, can_id, t_ns, b"" if rtr else bytes(data),
                          self._answering if seq is None else seq))

    def done(self, seq: int, error: bool = False) -> None:
        """End the exchange of frame ``seq``; ``error``: this client destroys
        it with a bus error (it models a fault on the bus: the sending
        controller counts the error and retransmits, every client gets
        ERROR, the answers to it are dropped)."""
        if self._answering == seq:
            self._answering = 0
        self._send(Record(DONE, DONE_ERROR if error else 0, seq=seq))

    def close(self) -> None:
        """Say BYE (if the socket still works) and close."""
        if self.sock.fileno() >= 0:
            try:
                if not self.closed:
                    self._send(Record(BYE))
            except OSError:
                pass
            self.sock.close()
        self.closed = True

    def __enter__(self) -> Link:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
