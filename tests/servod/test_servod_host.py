"""servod's pieces that need no board (session state machine, setpoint
sources, path error, request table, the parameter service against a
scripted servo on a host buffer, the bounds of what the servo answers), built for the host under
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


def test_servod_unit(tmp_path: Path) -> None:
    motion_build = TOP / "build" / "motion"
    subprocess.run(["make", "-s", "-C", str(TOP / "motion"), "host", f"BUILD={motion_build}"],
                   check=True)
    exe = tmp_path / "test_servod_unit"
    cmd = ["cc", "-std=c11", "-O1", "-g", "-Wall", "-Wextra", "-Werror", "-pthread",
           "-fsanitize=address,undefined", "-fno-sanitize-recover=all", "-fno-omit-frame-pointer",
           f"-I{TOP / 'amp_lib/include'}", f"-I{TOP / 'amp_lib/port/linux'}", f"-I{TOP / 'include'}",
           f"-I{TOP / 'linux/telemetry'}", f"-I{TOP / 'motion/include'}", f"-I{SERVOD}",
           f"-I{TOP / 'tests/amp_lib'}",
           str(Path(__file__).with_name("test_servod_unit.c")),
           *map(str, _servod_sources()),
           str(TOP / "amp_lib/src/amp_linux.c"), str(TOP / "amp_lib/src/amp_common.c"),
           str(TOP / "amp_lib/src/amp_servo.c"),
           str(TOP / "amp_lib/src/amp_strerror.c"), str(TOP / "linux/telemetry/telem.c"),
           str(motion_build / "host" / "libmotion.a"), "-lm", "-o", str(exe)]
    subprocess.run(cmd, check=True)
    proc = subprocess.run([str(exe)], capture_output=True, text=True, timeout=120)
    out = proc.stdout + proc.stderr
    print(out)
    assert proc.returncode == 0, out
    assert " 0 failed" in out and "runtime error" not in out, out
