# SPDX-License-Identifier: MIT
"""What a CANopen master sends and reads, for the fieldbus tests: SDO
expedited requests and responses, NMT, PDO payloads; a drive on a guest
clock (Bench) and QEMU's side of a canlink connection (Peer)."""

from __future__ import annotations

import socket
import struct
import threading
from pathlib import Path

from servoamp import canlink
from servoamp.canlink import HELLO, Record
from servoamp.drivesim import cia402
from servoamp.drivesim.cia402 import State
from servoamp.drivesim.drive import Drive, Frame, Injection

MS = 1_000_000
NODE = 3

NMT_START = 0x01
NMT_STOP = 0x02
NMT_PRE_OP = 0x80
NMT_RESET_NODE = 0x81
NMT_RESET_COMM = 0x82


def nmt(cs: int, node: int = 0) -> tuple[int, bytes]:
    return 0x000, bytes([cs, node])


def sdo_download(node: int, index: int, sub: int, value: int, size: int, signed: bool = False) -> tuple[int, bytes]:
    """An expedited SDO download request (1, 2 or 4 bytes)."""
    cmd = {1: 0x2F, 2: 0x2B, 4: 0x23}[size]
    data = value.to_bytes(size, "little", signed=signed).ljust(4, b"\0")
    return 0x600 + node, struct.pack("<BHB", cmd, index, sub) + data


def sdo_upload(node: int, index: int, sub: int) -> tuple[int, bytes]:
    return 0x600 + node, struct.pack("<BHB4x", 0x40, index, sub)


def sdo_response(data: bytes) -> tuple[str, int, int, int]:
    """(kind, index, sub, value): kind 'download-ok', 'upload' (value as
    unsigned, expedited with size) or 'abort' (value = abort code)."""
    assert len(data) == 8, data
    cmd, index, sub = struct.unpack_from("<BHB", data)
    value = struct.unpack_from("<I", data, 4)[0]
    if cmd == 0x60:
        return "download-ok", index, sub, 0
    if cmd == 0x80:
        return "abort", index, sub, value
    if cmd & 0xE3 == 0x43:          # expedited, size indicated
        n = 4 - ((cmd >> 2) & 3)
        return "upload", index, sub, int.from_bytes(data[4:4 + n], "little")
    raise AssertionError(f"unexpected SDO response {data.hex()}")


def rpdo1(node: int, controlword: int, target: int) -> tuple[int, bytes]:
    return 0x200 + node, struct.pack("<Hi", controlword, target)


def tpdo1(data: bytes) -> tuple[int, int]:
    """(statusword, position actual) of TPDO1."""
    sw, pos = struct.unpack("<Hi", data)
    return sw, pos


def emcy(data: bytes) -> tuple[int, int]:
    """(error code, error register) of an EMCY."""
    code, reg = struct.unpack_from("<HB", data)
    return code, reg


class Bench:
    """One drive and a guest clock."""

    def __init__(self, faults: list[Injection] | None = None, node: int = NODE,
                 fault_reset_cycles: int | None = 0) -> None:
        self.drive = Drive(node, faults=faults or [], fault_reset_cycles=fault_reset_cycles)
        self.node = node
        self.t = 0
        self.boot = self.drive.boot(0)

    def send(self, frame: tuple[int, bytes], dt_ns: int = 100_000) -> list[Frame]:
        self.t += dt_ns
        return self.drive.on_frame(frame[0], frame[1], self.t)

    def sdo(self, frame: tuple[int, bytes]) -> tuple[str, int, int, int]:
        out = [f for f in self.send(frame) if f.can_id == 0x580 + self.node]
        assert len(out) == 1, out
        return sdo_response(out[0].data)

    def cycle(self, cw: int, target: int) -> tuple[int, int, list[Frame]]:
        """RPDO then SYNC 1 ms after the last SYNC: (statusword, position, all frames)."""
        out = self.send(rpdo1(self.node, cw, target), 50_000)
        out += self.send((0x080, b""), 950_000)
        tp = [f for f in out if f.can_id == 0x180 + self.node]
        assert len(tp) == 1, out
        sw, pos = tpdo1(tp[0].data)
        return sw, pos, out

    def enable(self) -> None:
        self.send(nmt(NMT_START, self.node))
        assert self.sdo(sdo_download(self.node, 0x6060, 0, 8, 1))[0] == "download-ok"
        for cw in (0x06, 0x07, 0x0F):
            self.cycle(cw, 0)
        sw, _, _ = self.cycle(0x0F, 0)
        assert cia402.state_of(sw) == State.OPERATION_ENABLED


class Peer:
    """QEMU's side of one connection, as docs/canlink.md has it."""

    def __init__(self, path: Path) -> None:
        self.srv = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self.srv.bind(str(path))
        self.srv.listen(4)
        self.conn: socket.socket | None = None
        self.hello: Record | None = None
        self.ready = threading.Event()
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self) -> None:
        self.conn, _ = self.srv.accept()
        self.hello = self.read()
        self.write(Record(HELLO, can_id=500_000, t_ns=777))
        self.ready.set()

    def read(self) -> Record:
        assert self.conn is not None
        buf = b""
        while len(buf) < 32:
            chunk = self.conn.recv(32 - len(buf))
            assert chunk
            buf += chunk
        return canlink.unpack(buf)

    def write(self, rec: Record) -> None:
        assert self.conn is not None
        self.conn.sendall(canlink.pack(rec))

    def pending(self, timeout: float = 0.2) -> bool:
        assert self.conn is not None
        self.conn.settimeout(timeout)
        try:
            return bool(self.conn.recv(1, socket.MSG_PEEK))
        except TimeoutError:
            return False
        finally:
            self.conn.settimeout(None)
