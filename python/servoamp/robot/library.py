"""The EmulatedBoard keyword library (see the package docstring)."""

from __future__ import annotations

import re
import time
from pathlib import Path
from typing import Any

from robot.api import logger
from robot.api.deco import keyword, library

from servoamp.qemu import (
    Board,
    Images,
    QemuError,
    QemuMachine,
    Uart,
    boot_to_shell,
    default_clock,
    prepare_images,
    rproc_words,
    run_shell,
)


def _seconds(value: Any) -> float:
    """Robot time strings ("30 s", "1 min", "2.5") to seconds."""
    if isinstance(value, (int, float)):
        return float(value)
    from robot.utils import timestr_to_secs  # type: ignore[import-untyped]

    return float(timestr_to_secs(str(value)))


@library(scope="SUITE", auto_keywords=False)
class EmulatedBoard:
    """One emulated board per suite: build the images, boot, talk to it."""

    def __init__(self, board: str = "zynq7000_qemu", accel: str = "") -> None:
        self._board = Board.load(board)
        self._accel = accel or None
        self._images: Images | None = None
        self._machine: QemuMachine | None = None
        self._testers: list[tuple[Uart, float]] = []
        self._default: int | None = None
        self._failed = False
        self.ROBOT_LIBRARY_LISTENER = self

    # -- listener: keep the logs of a suite with a failed test -------------
    ROBOT_LISTENER_API_VERSION = 3

    def end_test(self, data: Any, result: Any) -> None:
        if not result.passed:
            self._failed = True

    def end_suite(self, data: Any, result: Any) -> None:
        if not result.passed:
            self._failed = True
        self.quit_emulation()

    # -- emulation ----------------------------------------------------------

    @keyword
    def build_images(self, *firmware: str) -> None:
        """Build or take from the caches kernel, module, initramfs, boot stub
        and DTB. Without arguments /lib/firmware gets the test fixtures and
        rpu_app's ELF(s) if built; otherwise the given ELF files."""
        t0 = time.monotonic()
        fw = [Path(f) for f in firmware] if firmware else None
        self._images = prepare_images(self._board, fw)
        logger.info(f"images ready in {time.monotonic() - t0:.1f} s: {self._images}")

    @keyword
    def set_emulation_accel(self, accel: str = "") -> None:
        """QEMU ``-accel`` value for the next Start Emulation, e.g.
        ``tcg,thread=single`` (empty: QEMU's default, multi-threaded TCG)."""
        self._accel = accel or None

    @keyword
    def emulation_clock(self) -> str:
        """``virtual`` (-icount: guest time counts instructions) or ``host``
        (guest time follows the host clock): $SERVOAMP_CLOCK, default
        virtual (docs/cycle-figures.md, "Emulation limits")."""
        return default_clock()

    @keyword
    def start_emulation(self) -> None:
        """Start QEMU (builds the images first if needed)."""
        if self._images is None:
            self.build_images()
        assert self._images is not None
        self._machine = QemuMachine(self._board, self._images, accel=self._accel)
        self._machine.start()
        logger.info(f"QEMU run directory: {self._machine.run_dir}")

    @keyword
    def quit_emulation(self) -> None:
        """Stop QEMU; its logs are kept if a test of the suite failed."""
        if self._machine is not None:
            if self._failed:
                self._machine.mark_failed()
            self._machine.stop()
            self._machine = None
        self._testers = []
        self._default = None

    @keyword
    def boot_to_shell(self, timeout: Any = "90 s") -> dict[str, float]:
        """Wait for the console shell; returns ``first_line``, ``shell`` (host
        seconds since QEMU start) and ``guest_userspace`` (guest uptime at
        /init)."""
        t = boot_to_shell(self._m, timeout=_seconds(timeout))
        logger.info(
            f"boot: first kernel line {t.first_line:.2f} s, shell {t.shell:.2f} s (host), "
            f"userspace at {t.guest_userspace:.2f} s guest uptime",
            also_console=True,
        )
        return {"first_line": t.first_line, "shell": t.shell, "guest_userspace": t.guest_userspace}

    @property
    def _m(self) -> QemuMachine:
        if self._machine is None or not self._machine.running:
            raise QemuError("the emulation is not running (Start Emulation)")
        return self._machine

    # -- Renode-style terminal testers ---------------------------------------

    @keyword
    def create_terminal_tester(self, uart: str, timeout: Any = "10 s", defaultPauseEmulation: Any = None) -> int:
        """Attach a tester to ``uart`` (a name from board.yaml, e.g. uart0,
        or Renode-style ``sysbus.uart0``); the first one becomes the default.
        Returns the tester id."""
        name = uart.split(".")[-1]
        self._testers.append((self._m.uart(name), _seconds(timeout)))
        tid = len(self._testers) - 1
        if self._default is None:
            self._default = tid
        return tid

    def _tester(self, testerId: Any) -> tuple[Uart, float]:
        if not self._testers:
            raise QemuError("no terminal tester (Create Terminal Tester)")
        tid = self._default if testerId in (None, "", "None") else int(testerId)
        assert tid is not None
        return self._testers[tid]

    @keyword
    def wait_for_line_on_uart(
        self, content: str, timeout: Any = None, testerId: Any = None, treatAsRegex: Any = False
    ) -> str:
        """Wait for a line containing ``content`` (or matching it as a
        regular expression); returns the line."""
        uart, default = self._tester(testerId)
        regex = str(treatAsRegex).lower() in ("true", "1", "yes")
        return uart.wait_for_line(content, timeout=_seconds(timeout) if timeout else default, regex=regex)

    @keyword
    def wait_for_prompt_on_uart(self, prompt: str = "", timeout: Any = None, testerId: Any = None) -> str:
        """Wait for ``prompt`` (default: the board's shell prompt), which
        need not end a line; returns the output before it."""
        uart, default = self._tester(testerId)
        prompt = prompt or str(self._board.data["linux"]["prompt"])
        out = uart.wait_for_text(prompt, timeout=_seconds(timeout) if timeout else default)
        return out[: -len(prompt)]

    @keyword
    def write_line_to_uart(self, line: str = "", testerId: Any = None, waitForEcho: Any = True) -> None:
        """Send ``line`` and a newline. With ``waitForEcho`` the tester's
        cursor moves past the echoed line."""
        uart, default = self._tester(testerId)
        uart.write_line(line)
        if str(waitForEcho).lower() in ("true", "1", "yes") and line:
            uart.wait_for_line(line[-40:], timeout=default)

    @keyword
    def clear_terminal_tester_report(self, testerId: Any = None) -> None:
        """Forget the output received so far."""
        self._tester(testerId)[0].skip()

    # -- monitor ---------------------------------------------------------------

    @keyword
    def execute_command(self, command: str, cpu: Any = None) -> str:
        """A QEMU monitor (HMP) command, e.g. ``xp /1wx 0xffff8004``;
        ``cpu`` selects the CPU for commands such as ``info registers``."""
        out = self._m.hmp(command, None if cpu in (None, "") else int(cpu))
        logger.info(out)
        return out

    @keyword
    def read_word(self, address: Any) -> int:
        """A 32-bit word of guest physical memory (through the monitor)."""
        return self._m.read_word(int(str(address), 0))

    @keyword
    def word_should_be(self, address: Any, expected: Any, timeout: Any = "0 s") -> float:
        """Fail unless the word at ``address`` equals ``expected`` within
        ``timeout``; returns the host seconds it took."""
        addr, want = int(str(address), 0), int(str(expected), 0)
        return self._m.wait_word(addr, want, timeout=_seconds(timeout))

    # -- shell -------------------------------------------------------------------

    @keyword
    def execute_shell_command(self, command: str, expected_rc: Any = 0, timeout: Any = "20 s", testerId: Any = None) -> str:
        """Run ``command`` in the console shell, wait for the prompt, check
        its exit status (``expected_rc``; ``any`` to skip) and return its
        output (without the echoed command)."""
        uart, _ = self._tester(testerId)
        prompt = str(self._board.data["linux"]["prompt"])
        rc, text = run_shell(uart, command, prompt, timeout=_seconds(timeout))
        logger.info(f"$ {command}\n{text}\n(rc={rc})")
        if str(expected_rc).lower() != "any" and rc != int(expected_rc):
            raise AssertionError(f"'{command}' exited with {rc}, expected {expected_rc}:\n{text}")
        return text

    @keyword
    def firmware_symbol(self, firmware: str, symbol: str) -> int:
        """Address of ``symbol`` in the ELF that the guest has as
        /lib/firmware/``firmware``."""
        from elftools.elf.elffile import ELFFile
        from elftools.elf.sections import SymbolTableSection

        if self._images is None:
            raise QemuError("no images (Build Images)")
        for path in self._images.firmware:
            if path.name == firmware:
                with path.open("rb") as f:
                    tab = ELFFile(f).get_section_by_name(".symtab")
                    if not isinstance(tab, SymbolTableSection):
                        raise AssertionError(f"{firmware}: no symbol table")
                    for sym in tab.iter_symbols():
                        if sym.name == symbol:
                            return int(sym["st_value"])
                raise AssertionError(f"{firmware}: no symbol {symbol}")
        raise AssertionError(f"{firmware} is not in the initramfs")

    @keyword
    def firmware_in_image(self, firmware: str) -> bool:
        """Whether /lib/firmware/``firmware`` is part of this boot."""
        if self._images is None:
            raise QemuError("no images (Build Images)")
        return any(p.name == firmware for p in self._images.firmware)

    @keyword
    def rproc_word(self, name: str) -> int:
        """A word of the start/stop contract, e.g. ``Rproc Word  ZSR_STATUS_PARKED``
        (include/servoamp/rproc_words.h)."""
        return rproc_words()[name]

    @keyword
    def board_value(self, *keys: str) -> Any:
        """A value from board.yaml, e.g. ``Board Value  servo  status_word``."""
        node: Any = self._board.data
        for k in keys:
            node = node[k]
        return node
