"""amp_lib on the host: unit tests, the two-process stress test and the
watchdog test, under the plain build and under sanitizers; the servo-side
footprint budget; the transport benchmark runs (figures are not judged)."""

from __future__ import annotations

import json
import queue
import re
import subprocess
import sys
import threading
from pathlib import Path

import pytest

TOP = Path(__file__).resolve().parents[2]
BUILD = TOP / "build" / "amp_lib"


def _make(san: str, *targets: str) -> Path:
    subprocess.run(["make", "-s", "-C", str(TOP / "amp_lib"), f"SAN={san}", *targets],
                   check=True)
    return BUILD / san


@pytest.fixture(scope="session")
def build_none() -> Path:
    return _make("none", "all", "bench")


@pytest.fixture(scope="session")
def build_asan() -> Path:
    return _make("asan", "all")


@pytest.fixture(scope="session")
def build_tsan() -> Path:
    return _make("tsan", "all")


def _run_watched(cmd: list[str], stall_s: float) -> str:
    """Run amp_stress lockstep, which prints a progress line every hundredth of
    its cycles, to the end however long the host's load makes it; fail if
    it makes no progress for stall_s (a livelock or a deadlock, not a slow
    host: a hundredth of 10M cycles takes ~3 s on a quiet core)."""
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines: queue.Queue[str | None] = queue.Queue()

    def read() -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            lines.put(line)
        lines.put(None)

    threading.Thread(target=read, daemon=True).start()
    out: list[str] = []
    while True:
        try:
            line = lines.get(timeout=stall_s)
        except queue.Empty:
            proc.kill()
            proc.wait()
            pytest.fail(f"no progress for {stall_s:.0f} s:\n{''.join(out)}")
        if line is None:
            break
        out.append(line)
    text = "".join(out)
    assert proc.wait() == 0, text
    return text


def _run(cmd: list[str], timeout: int) -> str:
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    out = proc.stdout + proc.stderr
    print(out)
    assert proc.returncode == 0, out
    assert "runtime error" not in out and "Sanitizer" not in out, out
    return out


@pytest.mark.parametrize("variant", ["none", "asan", "tsan"])
def test_unit(variant: str, request: pytest.FixtureRequest) -> None:
    build = request.getfixturevalue(f"build_{variant}")
    out = _run([str(build / "test_amp_unit")], timeout=120)
    assert " 0 failed" in out


@pytest.mark.parametrize("variant", ["none", "asan", "tsan"])
def test_hostile_peer_rewrites_ocm_between_reads(variant: str, request: pytest.FixtureRequest) -> None:
    """Issue 13, finding 10: the peer rewrites a frame or record in OCM at an
    exact point of the read (the posix port's load hook): nothing is accepted
    whose CRC does not match the bytes the caller gets; the application gets
    the validated copy, never OCM."""
    build = request.getfixturevalue(f"build_{variant}")
    out = _run([str(build / "test_amp_hostile")], timeout=60)
    assert " 0 failed" in out


@pytest.mark.parametrize("variant", ["none", "asan", "tsan"])
def test_reattach_resynchronises_feedback(variant: str, request: pytest.FixtureRequest) -> None:
    """Issue 20, item 4: after 1000 cycles, a stray 0 in fb_pub while the
    servo is down and a re-attach, feedback resumes within 2 cycles (it was
    999 cycles of AMP_RX_INVALID with AMP_OK); every word of the region set
    to each hostile value while the servo is down: feedback and commands
    resume within 2 cycles (3 for Linux's own header and line, which
    amp_linux_cycle writes again every cycle), or amp_linux_cycle returns
    AMP_E_STALLED / AMP_E_FEEDBACK within wd_limit + 2 cycles; and refused
    feedback reads are AMP_E_FEEDBACK from the wd_limit-th on, re-attach or
    not."""
    build = request.getfixturevalue(f"build_{variant}")
    out = _run([str(build / "test_amp_resync")], timeout=300)
    assert " 0 failed" in out
    assert "; 0 cycles AMP_OK+INVALID" in out
    assert re.search(r"every word: (\d+) scenarios, \d+ resumed within 2 \(Linux's own words: 3\) cycles,"
                     r" \d+ reported an error, 0 failed", out), out


@pytest.mark.slow
def test_stress_two_processes_10m_cycles_1m_mailbox(build_none: Path) -> None:
    out = _run_watched([str(build_none / "amp_stress"), "lockstep",
                        "--cycles", "10000000", "--mbox", "1000000"], stall_s=300)
    assert "OK: 10000000 periodic exchanges and 1000000 mailbox transactions" in out


@pytest.mark.slow
def test_stress_two_processes_asan_ubsan(build_asan: Path) -> None:
    out = _run_watched([str(build_asan / "amp_stress"), "lockstep",
                        "--cycles", "1000000", "--mbox", "100000", "--seed", "99"], stall_s=300)
    assert "OK: 1000000 periodic exchanges" in out


@pytest.mark.slow
def test_stress_two_threads_tsan(build_tsan: Path) -> None:
    out = _run_watched([str(build_tsan / "amp_stress"), "lockstep", "--threads",
                        "--cycles", "200000", "--mbox", "20000", "--seed", "7"], stall_s=300)
    assert "OK: 200000 periodic exchanges" in out
    assert "WARNING: ThreadSanitizer" not in out


@pytest.mark.parametrize("variant", ["none", "asan"])
def test_watchdog_pause_and_kill_detected(variant: str, request: pytest.FixtureRequest) -> None:
    build = request.getfixturevalue(f"build_{variant}")
    out = _run([str(build / "amp_stress"), "watchdog", "--period-us", "1000",
                "--limit", "20", "--ticks", "1500"], timeout=120)
    assert "OK: stalls detected within the limit, no false detection" in out


def test_stress_rejects_bad_parameters(build_none: Path) -> None:
    proc = subprocess.run([str(build_none / "amp_stress"), "lockstep", "--axes", "99"],
                          capture_output=True, text=True, timeout=30)
    assert proc.returncode == 2 and "bad parameters" in proc.stderr


def test_unit_with_the_firmware_crc(tmp_path: Path) -> None:
    """The unit test (CRC against its bit-at-a-time definition, mailbox
    frames) with the CRC the firmware builds (AMP_CFG_CRC_SLICE4=0, the
    nibble table) on the host: both ways give the same CRC."""
    exe = tmp_path / "test_amp_unit_nibble"
    sources = [str(TOP / "amp_lib" / "src" / s)
               for s in ("amp_common.c", "amp_linux.c", "amp_servo.c", "amp_strerror.c")]
    subprocess.run(["cc", "-std=c11", "-Wall", "-Wextra", "-Werror", "-Wpedantic", "-O2",
                    "-D_POSIX_C_SOURCE=200809L", "-DAMP_CFG_CRC_SLICE4=0",
                    f"-I{TOP}/amp_lib/include", f"-I{TOP}/amp_lib/src", f"-I{TOP}/amp_lib/port/posix",
                    f"-I{TOP}/tests/amp_lib", str(TOP / "tests" / "amp_lib" / "test_amp_unit.c"),
                    *sources, "-o", str(exe)], check=True, timeout=120)
    out = _run([str(exe)], timeout=120)
    assert " 0 failed" in out, out


@pytest.mark.parametrize("cc,port,flags", [
    ("arm-linux-gnueabihf-gcc", "linux", ["-D_POSIX_C_SOURCE=200809L", "-mcpu=cortex-a9"]),
    ("cc", "linux", ["-D_POSIX_C_SOURCE=200809L"]),
    ("arm-none-eabi-gcc", "baremetal-armv7", ["-mcpu=cortex-a9", "-ffreestanding",
                                              "-DAMP_BOARD_TICKS_PER_US=100", "-DAMP_CFG_OCM_CACHED=1"]),
    ("arm-none-eabi-gcc", "baremetal-armv7", ["-mcpu=cortex-r5", "-mthumb", "-ffreestanding",
                                              "-DAMP_BOARD_TICKS_PER_US=100"]),
])
def test_every_port_compiles_warning_free(cc: str, port: str, flags: list[str], tmp_path: Path) -> None:
    """Each port builds the sources its side uses with -Werror (the target
    Linux port for armhf, the bare-metal port with and without caches)."""
    sources = ["amp_common.c", "amp_linux.c", "amp_strerror.c"] if port == "linux" \
        else ["amp_common.c", "amp_servo.c"]
    for src in sources:
        subprocess.run([cc, "-std=c11", "-Wall", "-Wextra", "-Werror", "-Wpedantic", "-O2", *flags,
                        f"-I{TOP}/amp_lib/include", f"-I{TOP}/amp_lib/src",
                        f"-I{TOP}/amp_lib/port/{port}", "-c", str(TOP / "amp_lib" / "src" / src),
                        "-o", str(tmp_path / (src + ".o"))], check=True, timeout=120)


def test_servo_footprint_within_budget(tmp_path: Path) -> None:
    out_json = tmp_path / "footprint.json"
    subprocess.run([sys.executable, str(TOP / "bench" / "amp_footprint.py"),
                    "--json", str(out_json)], check=True, timeout=300)
    data = json.loads(out_json.read_text())
    for target in ("cortex-a9-thumb2", "cortex-r5-thumb2"):
        t = data["targets"][target]
        assert 0 < t["code"] <= 2048, (target, t)
        assert t["data"] + t["bss"] <= 64, (target, t)


def test_transport_bench_runs_and_writes_json(build_none: Path, tmp_path: Path) -> None:
    out_json = tmp_path / "transport.json"
    _run([str(build_none / "transport_bench"), "--iters", "2000", "--json", str(out_json)],
         timeout=300)
    data = json.loads(out_json.read_text())
    for key in ("a_amp_periodic", "b_amp_mailbox_16", "b_amp_mailbox_512",
                "c_cacheline_pingpong", "d_eventfd", "e_pipe"):
        lat = data["latency"][key]
        assert 0 < lat["p50"] <= lat["p99"] <= lat["p99_9"] <= lat["max"], (key, lat)
    assert set(data["ratios"]) >= {"a_over_c_p50", "a_over_c_p99_9", "d_over_a_p50"}
