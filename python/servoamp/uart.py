"""A UART of the emulated board on a TCP socket: wait for a line, a prompt or
any text, write a line. Part of the launcher that :mod:`servoamp.qemu`
re-exports."""

from __future__ import annotations

import re
import socket
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

from servoamp.board import QemuError
from servoamp.hoststall import NO_STALL, Deadline, StallMeter

ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]|\x1b[()][A-Za-z0-9]")


class Uart:
    """One UART of the board, connected through a TCP socket.

    Everything received is appended to a log file and to a buffer; the
    waits search the buffer from a cursor and move it past what matched, as
    Renode's terminal tester does. ANSI escape sequences and CR are removed.
    """

    def __init__(self, name: str, sock: socket.socket, log_path: Path,
                 on_timeout: Callable[[str], object] | None = None,
                 stall: StallMeter | None = None) -> None:
        self.name = name
        #: called (outside the lock) when a wait times out, before the
        #: QemuError: QemuMachine dumps both vCPUs' state there
        self.on_timeout = on_timeout
        #: the processes the guest's output depends on (QEMU and this one):
        #: a wait's timeout counts only the time the host let them run
        #: (servoamp.hoststall), at most hoststall.CAP times the timeout
        self.stall = stall
        self._sock = sock
        self._log = log_path.open("wb")
        self._buf = ""
        self._pos = 0
        self._cond = threading.Condition()
        self._closed = False
        self._thread = threading.Thread(target=self._reader, name=f"uart-{name}", daemon=True)
        self._thread.start()

    def _reader(self) -> None:
        pending = b""
        while True:
            try:
                data = self._sock.recv(4096)
            except OSError:
                data = b""
            if not data:
                break
            self._log.write(data)
            self._log.flush()
            pending += data
            # keep an incomplete escape sequence for the next chunk
            cut = pending.rfind(b"\x1b")
            if cut >= 0 and len(pending) - cut < 8 and not re.search(rb"\x1b\[[0-9;?]*[A-Za-z]", pending[cut:]):
                text, pending = pending[:cut], pending[cut:]
            else:
                text, pending = pending, b""
            clean = ANSI.sub("", text.decode("utf-8", "replace")).replace("\r", "")
            with self._cond:
                self._buf += clean
                self._cond.notify_all()
        with self._cond:
            self._closed = True
            self._cond.notify_all()

    def _wait(self, find: Any, timeout: float, what: str) -> str:
        # the time the host held QEMU (or this reader) off does not count:
        # the guest had none of it
        deadline = Deadline(timeout, self.stall or NO_STALL)
        with self._cond:
            while True:
                hit = find(self._buf, self._pos)
                if hit is not None:
                    start, end = hit
                    self._pos = end
                    return self._buf[start:end]
                left = deadline.left()
                if left <= 0 or self._closed:
                    tail = self._buf[self._pos:][-800:]
                    closed = self._closed
                    break
                self._cond.wait(min(left, 1.0))
        held = 0.0 if closed else deadline.held()
        if closed:
            state = "closed"
        elif held > 0.05:
            state = (f"{timeout:g} s, and {held:.1f} s more in which the host held QEMU off its CPUs: "
                     f"{deadline.wall():.1f} s in all")
        else:
            state = f"{timeout:g} s"
        extra = ""
        if not closed and self.on_timeout is not None:
            try:
                self.on_timeout(f"{self.name}: no {what} within {state}")
            except Exception as e:  # the dump must never hide the timeout
                extra = f"\n(vCPU state dump failed: {e})"
        raise QemuError(f"{self.name}: no {what} ({state}); unread output:\n{tail}{extra}")

    def wait_for_line(self, text: str, timeout: float = 10.0, regex: bool = False) -> str:
        """Wait for a line that contains ``text`` (or matches the regex) and
        return that whole line (without the newline)."""
        pat = re.compile(text, re.M) if regex else re.compile(re.escape(text))

        def find(buf: str, pos: int) -> tuple[int, int] | None:
            m = pat.search(buf, pos)
            if not m:
                return None
            start = buf.rfind("\n", 0, m.start()) + 1
            end = buf.find("\n", m.end())
            if end < 0:
                return None  # the line is not complete yet
            return max(start, pos), end + 1

        return self._wait(find, timeout, f"line matching {text!r}").rstrip("\n")

    def wait_for_text(self, text: str, timeout: float = 10.0) -> str:
        """Wait for ``text`` anywhere (no newline needed); return everything
        from the cursor to the end of the match."""

        def find(buf: str, pos: int) -> tuple[int, int] | None:
            i = buf.find(text, pos)
            return None if i < 0 else (pos, i + len(text))

        return self._wait(find, timeout, f"text {text!r}")

    def write(self, data: str) -> None:
        self._sock.sendall(data.encode())

    def write_line(self, line: str) -> None:
        self.write(line + "\n")

    @property
    def cursor(self) -> int:
        """Index in :attr:`output` up to which the waits have consumed."""
        with self._cond:
            return self._pos

    def unread(self) -> str:
        with self._cond:
            return self._buf[self._pos:]

    def skip(self) -> None:
        """Forget everything received so far."""
        with self._cond:
            self._pos = len(self._buf)

    @property
    def output(self) -> str:
        with self._cond:
            return self._buf

    def close(self) -> None:
        try:
            self._sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self._sock.close()
        self._thread.join(timeout=2)
        self._log.close()
