"""Issue 24, item 3, on the emulated board: the cycle at 4 kHz (250 us) for
100,000 cycles (25 guest seconds) with 0 missed on both sides, with all
8 axes (AMP_MAX_AXES, the most the exchange carries).

One boot on virtual time (-icount: guest time counts instructions, so the
result does not depend on the host's load), servod started, the firmware
started through remoteproc, then `ampctl param set axes 8` and
`cycle_period_us 250` (servod and the firmware both follow), and one
window of guest time between two `ampctl stats`. Everything asserted is a
counter of the guest (servod's and the firmware's), never host time:

- both sides ran at least 100,000 cycles in the window, and the firmware
  runs 8 axes at 250 us;
- 0 missed cycle interrupts on Linux (servod, from the events' own times)
  and 0 on the servo (the firmware's cycle handler, from the TTC);
- no torn or invalid record taken on either side, and every one of the
  servo's commands and Linux's feedback records fresh or at most stale
  (never missed).

The benchmark measures the same run with its figures (bench/cycle/
cycle_bench.py, "the long run"; docs/cycle-figures.md, "Figures")."""

from __future__ import annotations

import pytest

from servoamp import qemu

pytestmark = pytest.mark.board

CYCLES = 100_000
PERIOD_US = 250
AXES = 8
RPROC = "/sys/class/remoteproc/remoteproc0"


def _stats(console: qemu.Uart, prompt: str) -> dict[str, int]:
    rc, out = qemu.run_shell(console, "ampctl stats", prompt, timeout=60)
    assert rc == 0, out
    res = {}
    for k, _, v in (ln.partition("=") for ln in out.splitlines()):
        try:
            res[k] = int(v, 0)
        except ValueError:
            pass
    return res


def test_4khz_100k_cycles_8_axes_none_missed(board: qemu.Board, images: qemu.Images) -> None:
    prompt = str(board.data["linux"]["prompt"])
    with qemu.QemuMachine(board, images, accel="tcg,thread=single", clock="virtual") as m:
        qemu.boot_to_shell(m, timeout=120)
        c = m.uart(0)

        def sh(cmd: str, timeout: float = 60.0) -> str:
            rc, out = qemu.run_shell(c, cmd, prompt, timeout=timeout)
            assert rc == 0, f"{cmd!r} exited with {rc}:\n{out}"
            return out

        sh("dmesg -n 1")
        sh("(servod > /tmp/servod.log 2>&1 &)")
        sh("i=0; while ! grep -q 'waiting for the servo' /tmp/servod.log && [ $i -lt 600 ]; "
           "do sleep 0.05; i=$((i+1)); done; grep -q 'waiting for the servo' /tmp/servod.log")
        sh(f"echo rpu_app.elf > {RPROC}/firmware && echo start > {RPROC}/state")
        sh("i=0; while ! grep -q 'parameter set loaded' /tmp/servod.log && [ $i -lt 600 ]; "
           "do sleep 0.05; i=$((i+1)); done; grep -q 'parameter set loaded' /tmp/servod.log")
        # the suite's watchdog (tests/robot/04_cycle.robot); axes, then the rate
        sh("ampctl param set wd_limit 50 && ampctl param set axes 8 && "
           f"ampctl param set cycle_period_us {PERIOD_US} && sleep 0.2")
        a = _stats(c, prompt)
        # 2 periods on top: the window is between the two snapshots
        sh(f"sleep {(CYCLES + 2) * PERIOD_US / 1e6:.4f}", timeout=1800)
        b = _stats(c, prompt)
        sh("ampctl param set cycle_period_us 1000 && ampctl param set axes 4")

    def d(k: str) -> int:
        return b[k] - a[k]

    print(f"\n[4 kHz] linux: {d('linux.cycles')} cycles, missed {d('linux.missed_irq')}, late {d('linux.late')}, "
          f"feedback fresh/stale/missed/torn/invalid {d('linux.fb_fresh')}/{d('linux.fb_stale')}/"
          f"{d('linux.fb_missed')}/{d('linux.fb_torn')}/{d('linux.fb_invalid')}; servo: {d('servo.cycles')} cycles, "
          f"missed {d('servo.missed')}, commands fresh/stale/missed/torn/invalid {d('servo.cmd_fresh')}/"
          f"{d('servo.cmd_stale')}/{d('servo.cmd_missed')}/{d('servo.cmd_torn')}/{d('servo.cmd_invalid')}; "
          f"servo handler mean {b['servo.cycle_ticks.mean'] * 10} instructions, max {b['servo.cycle_ticks.max'] * 10}",
          flush=True)
    assert b["servo.axes"] == AXES and b["servo.period_us"] == PERIOD_US
    assert d("linux.cycles") >= CYCLES and d("servo.cycles") >= CYCLES
    assert d("linux.missed_irq") == 0
    assert d("servo.missed") == 0
    assert d("linux.fb_torn") == d("linux.fb_invalid") == d("linux.fb_missed") == 0
    assert d("servo.cmd_torn") == d("servo.cmd_invalid") == d("servo.cmd_missed") == 0
    assert d("linux.stalls") == 0 and d("servo.safestops") == 0
