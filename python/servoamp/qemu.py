"""Launch the emulated servoamp board in QEMU and talk to it.

The board's numbers come from ``boards/<board>/board.yaml`` (load addresses,
memory map, QEMU machine). This module

* builds what the launch needs and is cheap (boot stub, DTB with the
  initramfs location in /chosen) and, through :func:`prepare_images`, runs
  the cached build scripts for the rest (kernel, remoteproc module, test
  firmware, initramfs);
* starts QEMU with both CPUs pointed at the boot stub (``-device loader``;
  ``-kernel`` cannot boot this two-core machine), each UART connected to a
  TCP socket on 127.0.0.1 that this process listens on (QEMU connects as
  the client, so no port is ever guessed) and QMP on a unix socket;
* offers :class:`Uart` (wait for a line or a prompt, write a line) and
  :meth:`QemuMachine.hmp` / :meth:`QemuMachine.read_word` (monitor commands
  such as ``xp /1wx 0xffff8004``), with timeouts everywhere;
* shuts QEMU down cleanly (QMP ``quit``, then SIGTERM, then SIGKILL) and
  keeps the run directory (UART logs, QEMU stderr, command line) when
  something failed.

The launcher is split by concern; this module is its one front door and
re-exports every name (``from servoamp import qemu``; ``qemu.QemuMachine``,
``qemu.prepare_images``, ...):

* :mod:`servoamp.board`: the board (``board.yaml``), :class:`QemuError`;
* :mod:`servoamp.images`: the images of a boot and their builds;
* :mod:`servoamp.runner`: the QEMU command line and :class:`QemuMachine`;
* :mod:`servoamp.uart`: :class:`Uart`; :mod:`servoamp.qmp`: :class:`Qmp`;
* :mod:`servoamp.vcpu`: the vCPU state dump on a hang.
"""

from __future__ import annotations

from servoamp.board import REPO, Board, QemuError, _log, rproc_words
from servoamp.images import (
    KERNEL_MODULES,
    KERNELS,
    RPU_APP_IMAGES,
    RPU_APP_VARIANTS,
    Images,
    _run,
    board_kernel_dir,
    build_bl33,
    build_dtb,
    build_initramfs,
    build_modules,
    build_stub,
    build_test_firmware,
    build_tf_a,
    build_userland,
    default_kernel,
    guest_arch,
    kernel_dir,
    kernel_link,
    kernel_source,
    prepare_images,
    rpu_app_firmware,
)
from servoamp.qmp import Qmp, connect_unix
from servoamp.runner import (
    CAN_BUSES,
    CAN_LINK_OPTS,
    CLOCKS,
    QEMU_ANY_BOARD,
    BootTimes,
    QemuMachine,
    boot_args,
    boot_to_shell,
    can_args,
    check_qemu,
    clock_args,
    default_clock,
    interactive,
    iter_word_samples,
    machine_args,
    project_qemu,
    qemu_args,
    run_shell,
)
from servoamp.uart import ANSI, Uart
from servoamp.vcpu import Symbols, symbolise, vcpu_report

__all__ = [
    "ANSI", "CAN_BUSES", "CAN_LINK_OPTS", "CLOCKS", "KERNELS", "KERNEL_MODULES", "REPO", "RPU_APP_IMAGES",
    "RPU_APP_VARIANTS", "Board", "BootTimes", "Images", "QEMU_ANY_BOARD", "QemuError", "QemuMachine", "Qmp",
    "Symbols",
    "Uart", "_log", "_run", "board_kernel_dir", "boot_args", "boot_to_shell", "build_bl33", "build_dtb",
    "build_initramfs", "build_modules", "build_stub", "build_test_firmware", "build_tf_a", "build_userland",
    "can_args", "check_qemu", "clock_args", "connect_unix", "default_clock", "default_kernel", "guest_arch",
    "interactive", "iter_word_samples", "kernel_dir", "kernel_link", "kernel_source", "machine_args",
    "prepare_images", "project_qemu", "qemu_args", "rproc_words", "rpu_app_firmware", "run_shell",
    "symbolise", "vcpu_report",
]
