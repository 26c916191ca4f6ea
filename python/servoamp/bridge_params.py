"""The bridge's parameters: servod's table as the Foxglove parameters
capability sees it, the requests that read and set them through servod
(:class:`ServodParams`), the SDK servers' callbacks, and who may set
(:mod:`servoamp.bridge`, docs/recording.md "Live: who may connect").

Who may set is decided by the front (:mod:`servoamp.wsfront`), not by who
reaches a port: any local process can connect to the SDK's servers on
127.0.0.1 (their TLS keeps browsers out, not processes). So the read-write
server sets parameters only for the clients the front vouched for: after
relaying a client with the bridge's token, the front sends upstream, before
any byte of the client's, a ``getParameters`` whose request id is a one-time
secret it got from :class:`FrontAuth`; the server's callback sees that id and
the SDK's id of the connection it came on, and marks that connection. A
``setParameters`` from any other connection is refused like the read-only
server's, and changes nothing.
"""

from __future__ import annotations

import itertools
import secrets
import socket
import struct
import threading
from dataclasses import dataclass
from typing import Any, Iterator, Protocol

from foxglove import Parameter, ParameterType
from foxglove.websocket import ServerListener, StatusLevel

from servoamp import telemetry as tw

READ_ONLY = ("servoamp: this connection is read-only: parameters are set through the URL "
             "with the token that servoamp bridge printed")
NOT_VOUCHED = ("servoamp: parameters are set only through the bridge's port, with the URL "
               "and token that servoamp bridge printed: this connection did not come through it")
AUTH_PREFIX = "servoamp-front-"
MSG_REQUEST = 9   # client -> server: u32 id, text
REPLY_HDR = struct.Struct("<IiI")   # MSG_REPLY: u32 id, i32 status, u32 n, text
REQUEST_MAX = 256


class ParamError(Exception):
    """servod refused a parameter request (its message)."""

    def __init__(self, status: int, msg: str) -> None:
        super().__init__(msg)
        self.status = status


@dataclass
class ParamInfo:
    id: int
    name: str
    type: str   # u32, i32, f32
    unit: str
    min: float
    max: float
    value: float | int
    read_only: bool


def parse_param_list(text: str) -> dict[str, ParamInfo]:
    """servod's ``param list`` table (params.c): id name type unit min max default value [(ro)]."""
    out: dict[str, ParamInfo] = {}
    for line in text.splitlines()[1:]:
        f = line.split()
        if len(f) < 8 or not f[0].isdigit():
            continue
        typ = f[2]
        val: float | int = float(f[7]) if typ == "f32" else int(f[7])
        out[f[1]] = ParamInfo(int(f[0]), f[1], typ, "" if f[3] == "-" else f[3], float(f[4]),
                              float(f[5]), val, "(ro)" in f[8:])
    return out


def fox_param(name: str, typ: str, v: float | int) -> Parameter:
    if typ == "f32":
        return Parameter(name, value=float(v), type=ParameterType.Float64)
    return Parameter(name, value=int(v))


class ServodParams:
    """Parameters through servod, for :class:`servoamp.bridge.Bridge`:
    REQUEST frames on its telemetry connection (docs/telemetry.md
    "Requests"), each waiting for its REPLY."""

    sock: socket.socket | None
    send_lock: threading.Lock
    req_ids: Iterator[int]
    pending: dict[int, tuple[threading.Event, list[Any]]]
    pending_lock: threading.Lock
    request_timeout: float
    params: dict[str, ParamInfo]

    def _init_params(self, request_timeout: float) -> None:
        self.send_lock = threading.Lock()
        self.req_ids = itertools.count(1)
        self.pending = {}
        self.pending_lock = threading.Lock()
        self.request_timeout = request_timeout
        self.params = {}

    def request(self, text: str) -> str:
        """One REQUEST to servod: its output, or ParamError with its message."""
        data = text.encode()
        if len(data) > REQUEST_MAX:
            raise ParamError(1, "request too long")
        rid = next(self.req_ids) & 0xFFFFFFFF
        ev = threading.Event()
        slot: list[Any] = []
        with self.pending_lock:
            self.pending[rid] = (ev, slot)
        try:
            with self.send_lock:
                if self.sock is None:
                    raise ParamError(-3, "not connected to the controller")
                self.sock.sendall(tw.FRAME.pack(MSG_REQUEST, 0, 4 + len(data))
                                  + struct.pack("<I", rid) + data)
            if not ev.wait(self.request_timeout):
                raise ParamError(-4, f"no answer from the controller in {self.request_timeout} s")
        except OSError as e:
            raise ParamError(-3, f"not connected to the controller: {e}") from None
        finally:
            with self.pending_lock:
                self.pending.pop(rid, None)
        status, msg = slot
        if status != 0:
            raise ParamError(status, msg)
        return str(msg)

    def list_params(self) -> dict[str, ParamInfo]:
        self.params = parse_param_list(self.request("param list"))
        return self.params

    def set_param(self, name: str, value: float | int | str) -> float | int:
        """Set through servod: the value the servo took (ParamError if refused)."""
        if isinstance(value, float) and value.is_integer() and \
                self.params.get(name, None) is not None and self.params[name].type != "f32":
            value = int(value)
        out = self.request(f"param set {name} {value}")
        v = out.strip().split("=", 1)[1].split()[0]
        info = self.params.get(name)
        if info is not None:
            info.value = float(v) if info.type == "f32" else int(v)
            return info.value
        return float(v)

    def _on_reply(self, p: bytes) -> None:
        if len(p) < REPLY_HDR.size:
            return
        rid, status, n = REPLY_HDR.unpack_from(p)
        text = p[REPLY_HDR.size:REPLY_HDR.size + min(n, len(p) - REPLY_HDR.size)]
        with self.pending_lock:
            entry = self.pending.get(rid)
        if entry is not None:
            entry[1][:] = [status, text.decode("utf-8", "replace")]
            entry[0].set()

    def _fail_pending(self, why: str) -> None:
        with self.pending_lock:
            for ev, slot in self.pending.values():
                slot[:] = [-3, why]
                ev.set()


class FrontAuth:
    """One-time secrets the front sends upstream for a client with the token,
    and the SDK client ids they marked (the read-write server's)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._pending: set[str] = set()
        self._clients: set[int] = set()

    def issue(self) -> str:
        """A new secret, for one relayed connection."""
        nonce = AUTH_PREFIX + secrets.token_hex(16)
        with self._lock:
            self._pending.add(nonce)
        return nonce

    def redeem(self, request_id: str | None, client_id: int) -> bool:
        """True (and the client marked) if request_id is a secret not yet used."""
        if not request_id or not request_id.startswith(AUTH_PREFIX):
            return False
        with self._lock:
            if request_id not in self._pending:
                return False
            self._pending.discard(request_id)
            self._clients.add(client_id)
        return True

    def vouched(self, client_id: int) -> bool:
        with self._lock:
            return client_id in self._clients


class ParamHost(Protocol):
    """What the callbacks need of the bridge."""

    params: dict[str, ParamInfo]
    server: Any
    server_ro: Any
    front_auth: FrontAuth

    def list_params(self) -> dict[str, ParamInfo]: ...

    def set_param(self, name: str, value: float | int | str) -> float | int: ...

    def _subscription(self, writable: bool, client: int, topic: str, on: bool) -> None: ...


class Listener(ServerListener):
    """A WebSocket server's callbacks (called on the SDK's threads): the
    read-write server's sets from connections the front vouched for reach
    servod; every other set is refused with an error status."""

    def __init__(self, b: ParamHost, writable: bool) -> None:
        self.b = b
        self.writable = writable

    def _status(self, msg: str) -> None:
        srv = self.b.server if self.writable else self.b.server_ro
        if srv is not None:
            srv.publish_status(msg, StatusLevel.Error)

    def on_get_parameters(self, client: Any, param_names: list[str],
                          request_id: str | None = None) -> list[Parameter]:
        if self.writable and self.b.front_auth.redeem(request_id, int(client.id)):
            return []   # the front's secret: nothing to list
        try:
            ps = self.b.list_params()
        except ParamError as e:
            self._status(f"servoamp: parameters: {e}")
            return []
        return [fox_param(p.name, p.type, p.value) for p in ps.values()
                if not param_names or p.name in param_names]

    def _refuse(self, why: str, parameters: list[Parameter]) -> list[Parameter]:
        self._status(why)
        return [fox_param(i.name, i.type, i.value) for p in parameters
                if (i := self.b.params.get(p.name)) is not None]

    def on_set_parameters(self, client: Any, parameters: list[Parameter],
                          request_id: str | None = None) -> list[Parameter]:
        out: list[Parameter] = []
        if not self.writable:
            return self._refuse(READ_ONLY, parameters)
        if not self.b.front_auth.vouched(int(client.id)):
            return self._refuse(NOT_VOUCHED, parameters)
        if not self.b.params:
            try:
                self.b.list_params()
            except ParamError as e:
                self._status(f"servoamp: parameters: {e}")
                return []
        for p in parameters:
            info = self.b.params.get(p.name)
            if info is None:
                self._status(f"servoamp: no parameter {p.name!r}")
                continue
            v = p.get_value()
            try:
                if not isinstance(v, (int, float, str)) or isinstance(v, bool):
                    raise ParamError(6, f"{p.name}: a number is needed, got {v!r}")
                self.b.set_param(p.name, v)
            except ParamError as e:
                self._status(f"servoamp: param set {p.name} {v!s:.40}: refused: {e}")
            out.append(fox_param(info.name, info.type, info.value))
        return out

    def on_subscribe(self, client: Any, channel: Any) -> None:
        self.b._subscription(self.writable, int(client.id), str(channel.topic), True)

    def on_unsubscribe(self, client: Any, channel: Any) -> None:
        self.b._subscription(self.writable, int(client.id), str(channel.topic), False)

    def on_parameters_subscribe(self, param_names: list[str]) -> None:
        return None

    def on_parameters_unsubscribe(self, param_names: list[str]) -> None:
        return None
