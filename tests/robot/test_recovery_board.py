"""Issue 20, items 2 and 3, end to end on the emulated board: one boot with
networking, servod with its telemetry through the port forward, the
firmware running; every time measured in guest time from servod's own log
(``servod[SEC.MS]``, CLOCK_MONOTONIC of the guest, virtual under -icount).

- **Requests do not starve the supervisor.** A client on the host keeps two
  parameter requests in flight (the most one client may) through the
  telemetry connection while the firmware hangs: each takes servod up to
  200 ms (the mailbox timeout), and before, servod served them while they
  came and never got back to its supervisor; now the stall is reported and
  the firmware recovered within wd_limit + 1 s of the hang.
- **A firmware that fails after every attach is latched.** The guest's shell
  hangs the firmware again at each "parameter set loaded": after 3 restarts
  within 60 s the fourth stall latches a fault: `ampctl status` exits 3 and
  says why, remoteproc says offline, nothing is restarted; `ampctl fault
  reset` brings it back.
- **Linux's cycle goes on through a firmware restart** (issue 23, item 3).
  The cycle timer stands for the FPGA's: the firmware's stop leaves Linux's
  counter running and the restarted firmware takes up its period. A hang
  and its recovery at 1 kHz and at 4 kHz: the restarted firmware says it
  kept the running period, the period is the same after, and servod missed
  no cycle interrupt (at 4 kHz on the PREEMPT_RT kernel only: the default
  kernel's remoteproc work holds servod off for a period or two there).
- **A failed restart is retried with backoff and reported.** The firmware
  file is replaced by one remoteproc refuses: the restart fails, is
  retried 1 s later, fails again, is retried 2 s later with the good image
  back, and the servo is back; the log and `ampctl stats` count both
  failures.

On both boards (the fixture is parametrized by board, one boot each): on
the ZynqMP the upstream R5 driver has no report_crash, so a stall is
servod's own record there ("restarting the firmware (servod's record ...)",
docs/boot-flow-zynqmp.md), and its stop powers R5 0 down through TF-A;
the checks are the same. The servo core's remoteproc is found as servod
finds it (the mailbox node's servoamp,remoteproc), not by a board's name.

The same checks on the host, against servod's own code with remoteproc
played in a directory: tests/servod/test_servod_recovery.c."""

from __future__ import annotations

import re
import socket
import struct
import threading
import time
from typing import Any

import pytest

from board_params import BOARDS, board_images
from servoamp import netboard
from servoamp import telemetry as tw

pytestmark = pytest.mark.board

LOG = netboard.SERVOD_LOG
WD_LIMIT = 50                 # as tests/robot/04_cycle.robot: 10 trips on TCG hiccups
MSG_REQUEST, MSG_REPLY = 9, 10
REPLY_HDR = struct.Struct("<IiI")
SE_TIMEOUT = 4


class Pipeliner:
    """A telemetry client that keeps two `param get pos_kp` in flight."""

    def __init__(self, port: int, token: str) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=10)
        self.sock.sendall(tw.encode_auth(token))
        self.replies: list[int] = []          # the status of each answer
        self.stop = threading.Event()
        self.error: BaseException | None = None
        self.th = threading.Thread(target=self._run, daemon=True)
        self.next_id = 1

    def _send(self) -> None:
        data = b"param get pos_kp"
        self.sock.sendall(tw.FRAME.pack(MSG_REQUEST, 0, 4 + len(data))
                          + struct.pack("<I", self.next_id) + data)
        self.next_id += 1

    def _run(self) -> None:
        sp = tw.FrameSplitter()
        self.sock.settimeout(0.5)
        try:
            while not self.stop.is_set():
                try:
                    d = self.sock.recv(1 << 16)
                except socket.timeout:
                    continue
                if not d:
                    raise ConnectionError("servod closed the telemetry connection")
                sp.feed(d)
                for typ, off, ln in sp.frames():
                    if typ == tw.MSG_HELLO and self.next_id == 1:
                        self._send()
                        self._send()
                    elif typ == MSG_REPLY:
                        _rid, status, _n = REPLY_HDR.unpack_from(bytes(sp.buf[off:off + ln]))
                        self.replies.append(status)
                        self._send()
        except BaseException as e:  # reported by the test
            if not self.stop.is_set():
                self.error = e

    def start(self) -> Pipeliner:
        self.th.start()
        return self

    def close(self) -> None:
        self.stop.set()
        self.th.join(10)
        self.sock.close()


def _times(cb: netboard.ControllerBoard, text: str) -> list[float]:
    """Guest times (s) of servod's log lines with text."""
    out = cb.sh(f'grep -F "{text}" {LOG}', expected_rc=None)
    return [float(m.group(1)) for m in re.finditer(r"servod\[(\d+\.\d+)\]:", out)]


def _count(cb: netboard.ControllerBoard, text: str) -> int:
    return len(_times(cb, text))


def _delta(a: dict[str, str], b: dict[str, str], key: str) -> int:
    return int(b[key]) - int(a[key])


def _wait(text: str, count: int, guest_s: float = 60.0) -> str:
    """A guest shell loop until servod's log has text count times."""
    return (f'i=0; while [ "$(grep -c "{text}" {LOG})" -lt {count} ] && [ $i -lt {int(guest_s / 0.05)} ]; '
            f'do sleep 0.05; i=$((i+1)); done')


def _then_wait(cb: netboard.ControllerBoard, command: str, text: str, count: int) -> None:
    """command, then the wait, in ONE shell line: nothing is typed on the
    console while the firmware restarts. Console input arriving while
    remoteproc starts the firmware stopped CPU0's tick on this emulated
    board (the guest hung, its jiffies frozen at the start, CPU0 idle, the
    firmware running): 4 times in 4 when the next command was typed right
    after `ampctl fault reset` returned (servod starts the firmware a pass
    later), not once with the same steps and the shell busy meanwhile."""
    cb.sh(f"{command}; {_wait(text, count)}", timeout=120, expected_rc=None)
    got = _count(cb, text)
    if got < count:
        raise AssertionError(f"servod log has {got} x {text!r}, expected {count}:\n"
                             + cb.sh(f"cat {LOG}", expected_rc=None))


@pytest.fixture(scope="module", params=BOARDS)
def cb(request: pytest.FixtureRequest) -> Any:
    board, images = board_images(request.param)
    with netboard.ControllerBoard(board, images) as board:
        board.start_servod()
        board.start_firmware()
        board.wait_telemetry()
        board.ampctl(f"param set wd_limit {WD_LIMIT}")
        board.ampctl("resume", expected_rc=None)
        yield board


def test_cycle_goes_on_through_a_firmware_restart(cb: netboard.ControllerBoard) -> None:
    servo = cb.machine.uart(1) if cb.machine else None
    assert servo is not None
    rt = cb.kernel_rt()
    try:
        for period_us in (1000, 250):
            cb.ampctl(f"param set cycle_period_us {period_us}")
            cb.sh("sleep 0.5")
            n = _count(cb, "recovery complete")
            a = cb.stats()
            _then_wait(cb, "ampctl debug hang", "recovery complete", n + 1)
            cb.sh("sleep 0.5")   # the restored parameters applied
            b = cb.stats()
            kept = servo.wait_for_line(f"cycle: the cycle timer runs at {period_us} us (a restart)", 10)
            missed = _delta(a, b, "linux.missed_irq")
            print(f"[{cb.board.name}, {period_us} us, kernel {'PREEMPT_RT' if rt else 'not RT'}] restart: missed_irq {missed}, "
                  f"late {_delta(a, b, 'linux.late')}, cycles {_delta(a, b, 'linux.cycles')}; "
                  f"firmware: {kept.strip()}", flush=True)
            assert b["servo.state"] == "RUNNING"
            assert int(b["servo.period_us"]) == period_us, b
            if period_us == 1000 or rt:
                assert missed == 0, (period_us, a, b)
    finally:
        cb.ampctl("param set cycle_period_us 1000", expected_rc=None)


STOP_START_ROUNDS = 20


def test_back_to_back_stop_and_start_at_4khz_miss_no_cycle(cb: netboard.ControllerBoard) -> None:
    """The restart's hardest form for Linux's cycle: ``stop`` and ``start``
    through sysfs in one shell line, STOP_START_ROUNDS times at 4 kHz. On
    the ZynqMP each is EEMI calls through TF-A, which waits for the PMU
    stand-in's answer at EL3 with Linux's interrupts masked. A firmware
    restart at 4 kHz missed 4 cycle interrupts once, in a loaded `-n 2`
    run, and a probe of 20 such rounds missed 2 (docs/boot-flow-zynqmp.md,
    "What is left"); not seen since in 80 rounds on that QEMU build nor in
    any on today's (patch 0029: the stand-in answers at a fixed guest
    time). So every run checks it, on both boards: asserted where the
    kernel is PREEMPT_RT, as the restart above."""
    rt = cb.kernel_rt()
    cb.sh(f"R={cb.rproc}")
    try:
        cb.ampctl("param set cycle_period_us 250")
        cb.sh("sleep 0.5")
        a = cb.stats()
        regions0 = _count(cb, "region initialised")
        not_running = []
        for i in range(STOP_START_ROUNDS):
            n = _count(cb, "parameter set loaded")
            _then_wait(cb, "echo stop > $R/state; echo start > $R/state", "parameter set loaded", n + 1)
            st = cb.stats()
            if st["servo.state"] != "RUNNING":
                not_running.append(f"round {i}: {st['servo.state']} (fault {st.get('servo.fault')})")
                cb.ampctl("resume", expected_rc=None)
        cb.sh("sleep 0.5")
        b = cb.stats()
        missed = _delta(a, b, "linux.missed_irq")
        print(f"[{cb.board.name}, 250 us, kernel {'PREEMPT_RT' if rt else 'not RT'}] {STOP_START_ROUNDS} stops "
              f"and starts: missed_irq {missed}, late {_delta(a, b, 'linux.late')}, "
              f"cycles {_delta(a, b, 'linux.cycles')}; servod saw offline and made a new region in "
              f"{_count(cb, 'region initialised') - regions0} rounds", flush=True)
        # RUNNING: before, a round in which servod saw "offline" left the
        # new firmware on servod's old region, where Linux no longer beat,
        # and its watchdog stopped the axes (SAFESTOP, LINUX_STALL) before
        # servod took it back: 12 of 150 rounds here on the Zynq-7000.
        # servod closes its region with the session now (docs/cycle.md,
        # "A stop and a start in quick succession").
        assert not not_running and b["servo.state"] == "RUNNING", (
            f"servo not RUNNING after {len(not_running)} of {STOP_START_ROUNDS} rounds: {not_running}; "
            f"now {b['servo.state']}:\n" + cb.sh(f"tail -n 40 {LOG}", expected_rc=None))
        assert int(b["servo.period_us"]) == 250, b
        if rt:
            assert missed == 0, (a, b)
    finally:
        cb.ampctl("param set cycle_period_us 1000", expected_rc=None)


def test_pipelined_requests_do_not_hold_back_the_recovery(cb: netboard.ControllerBoard) -> None:
    n = _count(cb, "recovery complete")
    client = Pipeliner(cb.host_port, cb.token).start()
    try:
        deadline = time.monotonic() + 60
        while len(client.replies) < 4 and time.monotonic() < deadline and client.error is None:
            time.sleep(0.05)
        assert client.error is None and len(client.replies) >= 4, (client.error, client.replies)
        # before: no recovery while the client kept asking (waited here
        # until the timeout)
        # the guest's uptime (CLOCK_BOOTTIME, servod's CLOCK_MONOTONIC here:
        # nothing suspends) just before the hang is asked for
        _then_wait(cb, "cat /proc/uptime > /tmp/hang.t; ampctl debug hang", "recovery complete", n + 1)
        during = list(client.replies)
        assert client.error is None, client.error
    finally:
        client.close()
    b = cb.stats()
    hang = float(re.findall(r"^(\d+\.\d+) \d+\.\d+$", cb.sh("cat /tmp/hang.t"), re.M)[-1])
    stalled = _times(cb, "servo stalled")[-1]      # both drivers: servod's log line names the stall
    back = _times(cb, "recovery complete")[-1]
    print(f"[recovery {cb.board.name}] hang asked at {hang:.2f} s, stall reported at {stalled:.3f} s "
          f"({b['linux.last_stall_cycles']} cycles after the last heartbeat), recovered at {back:.3f} s "
          f"(guest): {back - hang:.3f} s; {len(during)} answers, {during.count(SE_TIMEOUT)} of them timeouts",
          flush=True)
    # the client was being served while the servo hung: its answers are timeouts
    assert during.count(SE_TIMEOUT) >= 1
    assert int(b["linux.last_stall_cycles"]) <= WD_LIMIT + 1
    # within wd_limit + 1 s of the hang (uptime's 10 ms steps on top)
    assert back - hang <= WD_LIMIT / 1000 + 1.0 + 0.01
    assert b["servo.state"] == "RUNNING"


def test_firmware_failing_after_every_attach_is_latched(cb: netboard.ControllerBoard) -> None:
    cb.ampctl("fault reset", expected_rc=None)     # forgets the restarts of the other cases
    n_latched = _count(cb, "the axes disabled until")
    a = cb.stats()
    # the firmware hangs again each time its parameter set is loaded
    cb.sh(f"touch /tmp/hangloop.on; ( ( last=$(grep -c 'parameter set loaded' {LOG}); "
          f"while [ -e /tmp/hangloop.on ]; do n=$(grep -c 'parameter set loaded' {LOG}); "
          f"if [ $n -gt $last ]; then last=$n; ampctl debug hang >/dev/null 2>&1; fi; sleep 0.01; done "
          f") >/dev/null 2>&1 & )")
    try:
        _then_wait(cb, "ampctl debug hang", "the axes disabled until", n_latched + 1)
    finally:
        cb.sh("rm -f /tmp/hangloop.on")
    st = cb.ampctl("status", expected_rc=3)
    print(st, flush=True)
    assert ("fault latched (servo stalled (heartbeat still for 50 cycles); 3 restarts within 60 s "
            "(limit 3)): the firmware is stopped; `ampctl fault reset` restarts it") in st
    assert "latched=1" in st and "session=fault" in st
    assert cb.sh(f"cat {cb.rproc}/state").strip().splitlines()[-1] == "offline"
    b = cb.stats()
    assert _delta(a, b, "linux.recoveries") == 3
    assert _delta(a, b, "linux.latches") == 1
    # nothing restarted while latched
    cb.sh("sleep 2")
    c = cb.stats()
    assert _delta(b, c, "linux.recoveries") == 0
    assert cb.sh(f"cat {cb.rproc}/state").strip().splitlines()[-1] == "offline"
    # the operator's reset
    n = _count(cb, "recovery complete")
    _then_wait(cb, "ampctl fault reset > /tmp/reset.out 2>&1", "recovery complete", n + 1)
    assert "fault reset: restarting the servo" in cb.sh("cat /tmp/reset.out")
    assert "after the operator's fault reset" in cb.sh(f"grep 'recovery complete' {LOG} | tail -n 1")
    st = cb.ampctl("status")
    assert "latched=0" in st and "link=attached" in st
    # the default board's axes are the firmware's internal models (no CAN drive)
    assert "axis0.drive=internal axis0.error=0x0000" in st, st
    d = cb.stats()
    cb.sh("sleep 0.5")
    e = cb.stats()
    assert _delta(d, e, "linux.exchanges") > 0
    assert e["servo.state"] == "RUNNING"


def test_failed_restart_is_retried_with_backoff(cb: netboard.ControllerBoard) -> None:
    cb.ampctl("fault reset", expected_rc=None)
    a = cb.stats()
    n = _count(cb, "recovery complete")
    fw = "/lib/firmware/rpu_app.elf"
    cb.sh(f"cp {fw} /tmp/rpu_app.elf.good && echo 'not a firmware' > {fw}")
    try:
        # the hang, two failed restarts, the image back, the third restart
        _then_wait(cb, f"ampctl debug hang; {_wait('recovery: restart 2 failed', 1)}; "
                   f"cp /tmp/rpu_app.elf.good {fw}", "recovery complete", n + 1)
    finally:
        cb.sh(f"cp /tmp/rpu_app.elf.good {fw}")
    log = cb.sh(f"grep -E 'recovery: restart|recovery complete' {LOG} | tail -n 5")
    print(log, flush=True)
    failed1 = _times(cb, "recovery: restart 1 failed")[-1]
    retry1 = _times(cb, "recovery: restart 2 (retry 1)")[-1]
    failed2 = _times(cb, "recovery: restart 2 failed")[-1]
    retry2 = _times(cb, "recovery: restart 3 (retry 2)")[-1]
    assert "restart 1 failed (start: " in log and "retry in 1 s" in log and "retry in 2 s" in log
    # the backoff, in guest time: 1 s, then 2 s (a pass of the main loop late at most)
    # (log times are in whole ms: 0.99, not 1.0)
    assert 0.99 <= retry1 - failed1 <= 1.5
    assert 1.99 <= retry2 - failed2 <= 2.5
    assert "recovery complete (restart 3, after retries)" in log
    b = cb.stats()
    assert _delta(a, b, "linux.recovery_failures") == 2
    assert _delta(a, b, "linux.recovery_retries") == 2
    assert _delta(a, b, "linux.recoveries") == 1
    assert _delta(a, b, "linux.latches") == 0
    assert "Image is too small" in cb.sh("dmesg | tail -n 40")   # the kernel refused the start
    assert b["servo.state"] == "RUNNING"
