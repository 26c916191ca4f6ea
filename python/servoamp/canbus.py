# SPDX-License-Identifier: MIT
"""python-can interface ``servoamp``: a bus on the emulated CAN bus of our
QEMU through its canlink backend (docs/canlink.md, docs/fieldbus.md).

Registered in the ``can.interface`` entry-point group, so every python-can
tool takes it unchanged::

    can.Bus(interface="servoamp", channel="build/can0.sock")
    python -m can.viewer -i servoamp -c build/can0.sock
    python -m can.logger -i servoamp -c build/can0.sock -f bus.asc
    canopen.Network().connect(interface="servoamp", channel="build/can0.sock")

Passive by default: QEMU never waits for this client, frames sent through
it reach the bus at the guest time QEMU reads them (host-dependent).

``listen_only=True`` makes a listener (a logger that must not miss a
frame): QEMU holds the guest on every frame until it sent DONE, like an
active client, but it sends nothing and gets only the frames no client
destroyed, as a CAN controller in listen-only mode would (a frame destroyed
by a bus error reaches it as an error frame alone).

``active=True`` makes an active client: QEMU holds the guest on every frame
it sends until this client sends DONE. The DONE for a frame returned by
:meth:`recv` goes out when the application calls :meth:`recv` again (or
:meth:`shutdown`); frames it sends in between are that frame's answers,
delivered at modelled bus time. A canopen Network's notifier calls the
callbacks of a frame before it reads the next one, so a canopen LocalNode
answers in lockstep. An application that does not call recv within QEMU's
``timeout-ms`` loses its answers (and after ``max-timeouts`` the link).

Message.timestamp is the guest time in seconds: the end of the frame on the
modelled bus. Received frames have ``is_rx`` True; frames other clients put
on the bus (INFO records) are received like the guest's. A frame destroyed
by a bus error (canlink ERROR: another client models a fault on the bus) is
received as an error frame (``is_error_frame``, its identifier, timestamp
the end of the error frame).
"""

from __future__ import annotations

from typing import Any

import can

from servoamp import canlink


class ServoampBus(can.BusABC):
    """A python-can bus on a canlink socket (``channel`` = its path)."""

    def __init__(self, channel: Any, can_filters: Any = None, active: bool | str = False,
                 name: str = "pycan", connect_timeout: float = 10.0, listen_only: bool | str = False,
                 **kwargs: Any) -> None:
        if not isinstance(channel, str) or not channel:
            raise can.CanInitializationError("servoamp: channel must be the canlink socket path")
        # from a command line: --bus-kwargs active=true listen_only=true
        active, listen_only = (v.strip().lower() in ("1", "true", "yes", "on") if isinstance(v, str) else bool(v)
                               for v in (active, listen_only))
        try:
            self._link = canlink.Link.connect(channel, active=active, name=name,
                                              timeout=float(connect_timeout), listen=listen_only)
        except (OSError, canlink.ProtocolError) as exc:
            raise can.CanInitializationError(f"servoamp: {channel}: {exc}") from exc
        self.active = self._link.active
        self.listen_only = listen_only
        self.bitrate = self._link.bitrate
        mode = "listen-only" if listen_only else "active" if active else "passive"
        self.channel_info = f"servoamp canlink {channel} ({mode}, {self.bitrate} bit/s)"
        self._channel = channel
        self._owed_done: int | None = None
        super().__init__(channel=channel, can_filters=can_filters, **kwargs)

    def _pay_done(self) -> None:
        if self._owed_done is not None:
            seq, self._owed_done = self._owed_done, None
            try:
                self._link.done(seq)
            except OSError as exc:
                raise can.CanOperationError(f"servoamp: DONE {seq}: {exc}") from exc

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        self._pay_done()
        try:
            rec = self._link.recv(timeout)
        except (OSError, canlink.ProtocolError) as exc:
            raise can.CanOperationError(f"servoamp: {self._channel}: {exc}") from exc
        if rec is None:
            return None, False
        if rec.type == canlink.BYE:
            raise can.CanOperationError(f"servoamp: {self._channel}: QEMU said BYE (the bus is gone)")
        if rec.type == canlink.ERROR:
            # a frame destroyed by a bus error: python-can's error frame
            return can.Message(timestamp=rec.t_ns / 1e9, arbitration_id=rec.can_id,
                               is_extended_id=rec.eff, is_error_frame=True, dlc=0,
                               is_rx=True, channel=self._channel, check=False), False
        if self.active and not rec.info:
            self._owed_done = rec.seq
        msg = can.Message(timestamp=rec.t_ns / 1e9, arbitration_id=rec.can_id,
                          is_extended_id=rec.eff, is_remote_frame=rec.rtr, dlc=rec.dlc,
                          data=rec.data, is_rx=True, channel=self._channel, check=False)
        return msg, False

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if self.listen_only:
            raise can.CanOperationError("servoamp: a listen-only bus sends nothing")
        if msg.is_error_frame or msg.is_fd:
            raise can.CanOperationError("servoamp: classic data and remote frames only")
        if not 0 <= msg.dlc <= 8:
            raise can.CanOperationError(f"servoamp: dlc {msg.dlc} over 8")
        data = b"" if msg.is_remote_frame else bytes(msg.data[: msg.dlc]).ljust(msg.dlc, b"\0")
        try:
            self._link.send_frame(msg.arbitration_id, data, eff=msg.is_extended_id,
                                  rtr=msg.is_remote_frame, dlc=msg.dlc)
        except (OSError, canlink.ProtocolError) as exc:
            raise can.CanOperationError(f"servoamp: send: {exc}") from exc

    def shutdown(self) -> None:
        if not self._is_shutdown:
            try:
                self._pay_done()
            except can.CanOperationError:
                pass
            self._link.close()
        super().shutdown()
