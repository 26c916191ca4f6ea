"""servod's pieces that need no board (session state machine, setpoint
sources, path error, request table, the parameter service against a
scripted servo on a host buffer, the bounds of what the servo answers; the
recovery's bounds and the main loop's with the supervisor, the cycle thread
and the telemetry server running), built for the host under
AddressSanitizer + UBSan with every servod file but main.c."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

TOP = Path(__file__).resolve().parents[2]
SERVOD = TOP / "linux" / "servod"


def _servod_sources() -> list[Path]:
    mk = (SERVOD / "Makefile").read_text()
    block = re.search(r"^SERVOD_SRCS :=(.*?)\n\n", mk, re.S | re.M)
    assert block, "SERVOD_SRCS not found in linux/servod/Makefile"
    names = block.group(1).replace("\\", " ").split()
    return [SERVOD / n for n in names if n != "main.c"]


def _telem_sources() -> list[Path]:
    mk = (TOP / "linux/telemetry/sources.mk").read_text()
    line = re.search(r"^TELEM_SOURCES :=(.*)$", mk, re.M)
    assert line, "TELEM_SOURCES not found in linux/telemetry/sources.mk"
    return [TOP / "linux/telemetry" / n for n in line.group(1).split()]


def _build_and_run(tmp_path: Path, source: str, name: str, link: tuple[str, ...] = (),
                   extra: tuple[str, ...] = ()) -> str:
    motion_build = TOP / "build" / "motion"
    subprocess.run(["make", "-s", "-C", str(TOP / "motion"), "host", f"BUILD={motion_build}"],
                   check=True)
    exe = tmp_path / Path(source).stem
    cmd = ["cc", "-std=c11", "-O1", "-g", "-Wall", "-Wextra", "-Werror", "-pthread",
           "-fsanitize=address,undefined", "-fno-sanitize-recover=all", "-fno-omit-frame-pointer",
           f"-I{TOP / 'amp_lib/include'}", f"-I{TOP / 'amp_lib/port/linux'}", f"-I{TOP / 'include'}",
           f"-I{TOP / 'linux/telemetry'}", f"-I{TOP / 'motion/include'}", f"-I{SERVOD}",
           f"-I{TOP / 'tests/amp_lib'}",
           str(Path(__file__).with_name(source)), *(str(Path(__file__).with_name(e)) for e in extra),
           *map(str, _servod_sources()),
           str(TOP / "amp_lib/src/amp_linux.c"), str(TOP / "amp_lib/src/amp_common.c"),
           str(TOP / "amp_lib/src/amp_servo.c"),
           str(TOP / "amp_lib/src/amp_strerror.c"), *map(str, _telem_sources()),
           str(motion_build / "host" / "libmotion.a"), "-lm", *link, "-o", str(exe)]
    subprocess.run(cmd, check=True)
    proc = subprocess.run([str(exe)], capture_output=True, text=True, timeout=300)
    out = proc.stdout + proc.stderr
    print(out)
    assert proc.returncode == 0, out
    assert " 0 failed" in out and "runtime error" not in out, out
    return out


def test_servod_unit(tmp_path: Path) -> None:
    _build_and_run(tmp_path, "test_servod_unit.c", "servod unit")


def test_servod_recovery(tmp_path: Path) -> None:
    """Issue 20, items 2 and 3: servod's supervisor, cycle thread and
    telemetry server against a servo on a host buffer and remoteproc played
    in a directory (test_servod_recovery.c): a firmware that fails after
    every attach ends in a latched fault after 3 restarts, reset by the
    operator; a failed restart is retried with backoff, and latched when it
    keeps failing; pipelined telemetry requests do not hold the stall's
    report back; a restarted firmware that attaches inside the cycle that
    judged the old one stalled is not blamed for that stall, and its own
    stall is reported (the cycle's telemetry hook wrapped by the linker to
    attach it there)."""
    _build_and_run(tmp_path, "test_servod_recovery.c", "servod recovery",
                   link=("-Wl,--wrap=telemetry_cycle",), extra=("recovery_rig.c",))


def test_servod_recovery_stop(tmp_path: Path) -> None:
    """Issue 33, item 1 and issue 35, item 3, on the same rig
    (recovery_rig.c): an operator's stop through remoteproc is never a
    crash (with and without the firmware's STOPPING word, between two
    passes, during a recovery); a remoteproc without report_crash (the
    ZynqMP's upstream R5 driver): the restart, the parameter restore, the
    latch and the fault reset through state alone, said once in servod's
    log instead of an error at each stall (test_servod_recovery_stop.c)."""
    _build_and_run(tmp_path, "test_servod_recovery_stop.c", "servod recovery (stop)",
                   link=("-Wl,--wrap=telemetry_cycle",), extra=("recovery_rig.c",))
