# SPDX-License-Identifier: MIT
"""What a CANopen master sends and reads, for the fieldbus tests: SDO
expedited requests and responses, NMT, PDO payloads."""

from __future__ import annotations

import struct

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
