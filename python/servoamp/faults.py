"""Fault injection on the running emulated controller.

One boot of the board (with networking, :class:`servoamp.netboard.ControllerBoard`),
servod and the servo firmware running the sine, a recorder on servod's
telemetry for the whole campaign, then each fault of :data:`FAULTS` in turn,
injected from the guest's shell while the cycle runs (``devmem`` on the OCM
region and on the GIC distributor, or a firmware debug hook), and what
followed read from both sides' counters (``ampctl stats``), servod's log and
the kernel's. For each fault:

- **detected by**: which side saw it, and the counter or log line that says so;
- **cycles**: how many cycles it took (from the counters where they carry it);
- **axes stopped**: the servo stopped commanding the axes (safe stop, or the
  firmware restarted by remoteproc's recovery), where the fault calls for it;
- **recovered**: the link attached and the exchange running again, without
  anyone's help, within the campaign's guest-time budget;
- **crashes**: servod still running, no kernel oops;
- and at the end, **data lost**: every cycle servod handled is in the
  recording, or accounted for by a gap the recording declares.

    python -m servoamp.faults [--json FILE] [--markdown] [NAME...]

The table in docs/reliability.md is this command's ``--markdown`` output;
tests/robot/test_faults.py runs it on the board in the test suite and
requires every fault detected and recovered, no crash and no loss.

Addresses come from the OCM layout (amp_lib/include/amp/amp_ocm_layout.h,
docs/amp-protocol.md) at the board's mailbox base, with AMP_CACHE_LINE 32 and
AMP_MAX_AXES 8 (the defaults the board builds with; tests/amp_lib checks the
offsets) and, for the cycle interrupts, from the board's ``fault_injection``
entry (board.yaml: the GIC distributor and interrupt ID of each side's
cycle interrupt). A fault that needs what a board does not give (the
ZynqMP's servo interrupt is taken at the RPU's GIC, which Linux cannot
reach) is skipped there with the reason, in the result and the table.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable

from servoamp import info, netboard, qemu
from servoamp import record as rec

# -- addresses ---------------------------------------------------------------------
LINE = 32                              # AMP_CACHE_LINE
OFF_SERVO_LINE = 2 * LINE              # struct amp_servo_line
OFF_CYC_SEM = 3 * LINE
OFF_MBOX_SEM = 4 * LINE
OFF_CMD = 5 * LINE
CMD_RECORD = 192                       # AMP_CMD_RECORD_SIZE (8 axes)
FB_RECORD = 224                        # AMP_FB_RECORD_SIZE (8 axes)
OFF_FB = OFF_CMD + 2 * CMD_RECORD
OFF_REQ = OFF_FB + 2 * FB_RECORD
FRAME = 544                            # AMP_FRAME_SIZE (512-byte payload)
OFF_RESP = OFF_REQ + FRAME
FB_N_AXES_WORD = 6                     # struct amp_fb_record: n_axes
HDR_LENGTH_WORD = 6                    # struct amp_frame_hdr: length
HDR_STATUS_WORD = 5
SEM_IDLE, SEM_BUSY = 1, 0
AMP_E_PROTO = -4

GICD_ISENABLER = 0x100                 # GIC distributor: set-enable, clear-enable
GICD_ICENABLER = 0x180

SETTLE_S = 1.0                         # guest seconds to let a recovery run
# servod's options for the campaign: it restarts the firmware on purpose more
# than 3 times a minute, which would latch servod's fault (docs/cycle.md,
# "Recovery and the fault latch"); the latch has its own test
SERVOD_ARGS = "--recovery-limit 0"


@dataclass(frozen=True)
class Irq:
    """A cycle interrupt as Linux's shell can mask it: its GIC distributor
    and interrupt ID (board.yaml fault_injection)."""
    gicd: int
    id: int


def board_irqs(board: qemu.Board) -> dict[str, Irq | None]:
    """The board's fault_injection entry: servo_irq and linux_irq, each an
    :class:`Irq` or None (the board says why in board.yaml)."""
    fi = board.data.get("fault_injection") or {}
    return {k: (Irq(int(v["gicd"]), int(v["id"])) if v else None)
            for k, v in ((k, fi.get(k)) for k in ("servo_irq", "linux_irq"))}


def irq_off(irq: Irq, usec: int | None = None) -> str:
    """Guest shell: disable a GIC interrupt at the distributor, and with
    usec enable it again after that long."""
    bank, bit = 4 * (irq.id // 32), 1 << (irq.id % 32)
    cmd = f"devmem 0x{irq.gicd + GICD_ICENABLER + bank:08x} 32 0x{bit:x}"
    if usec is not None:
        cmd += f"; usleep {usec}; devmem 0x{irq.gicd + GICD_ISENABLER + bank:08x} 32 0x{bit:x}"
    return cmd


@dataclass
class Outcome:
    name: str
    fault: str
    detected_by: str = ""
    cycles: str = ""
    axes_stopped: str = ""
    recovered: bool = False
    recovery: str = ""
    crashes: int = 0
    notes: list[str] = field(default_factory=list)
    ok: bool = False
    skipped: str = ""       # why this fault cannot be injected on this board


@dataclass
class Campaign:
    cb: netboard.ControllerBoard
    ocm: int
    wd_limit: int = 10
    irqs: dict[str, Irq | None] = field(default_factory=dict)
    # how a stall ends: a crash reported to remoteproc, whose recovery
    # restarts the firmware (a driver with report_crash, the Zynq-7000's),
    # or servod's own stop and start (the ZynqMP's upstream R5 driver)
    report_crash: bool = True

    def irq(self, which: str) -> Irq:
        i = self.irqs.get(which)
        assert i is not None, which
        return i

    def sh(self, cmd: str, timeout: float = 30.0) -> str:
        return self.cb.sh(cmd, timeout=timeout, expected_rc=None)

    def stats(self) -> dict[str, str]:
        return self.cb.stats()

    def log_count(self, text: str) -> int:
        out = self.sh(f'grep -c "{text}" {netboard.SERVOD_LOG}').strip().splitlines()
        return int(out[-1]) if out and out[-1].isdigit() else 0

    def attached(self) -> bool:
        return "link=attached" in self.sh("ampctl status 2>&1")

    def wait_attached_and_running(self, guest_s: float = 10.0,
                                  state: str = "RUNNING") -> tuple[bool, dict[str, str]]:
        """The link attached, the servo in `state` and exchanges advancing,
        within guest_s of guest time (the shell's sleeps run on the guest
        clock)."""
        n = int(guest_s / 0.25)
        for _ in range(n):
            a = self.stats()
            if a.get("servo.state") == state and self.attached():
                self.sh("sleep 0.25")
                b = self.stats()
                if int(b.get("linux.exchanges", 0)) > int(a.get("linux.exchanges", 0)) and \
                        b.get("servo.state") == state:
                    return True, b
            self.sh("sleep 0.25")
        return False, self.stats()

    def alive(self) -> int:
        """Crashes seen: servod gone, or a kernel oops/BUG."""
        crashes = 0
        if self.sh("pidof servod >/dev/null && echo up || echo down").strip().endswith("down"):
            crashes += 1
        crashes += int(self.sh("dmesg | grep -c -E 'Oops|BUG:|Unable to handle' || true")
                       .strip().splitlines()[-1] or 0)
        return crashes

    def word(self, off: int) -> str:
        return f"0x{self.ocm + off:08x}"

    def read_word(self, off: int) -> int:
        """A word of the amp_lib region, read with devmem."""
        return int(self.sh(f"devmem {self.word(off)} 32").strip().splitlines()[-1], 16)


def _delta(a: dict[str, str], b: dict[str, str], key: str) -> int:
    return int(b.get(key, 0)) - int(a.get(key, 0))


# -- the faults ------------------------------------------------------------------------

def _stall_seen(c: Campaign, o: Outcome, before: dict[str, str]) -> None:
    """After a fault that stops the servo's heartbeat: Linux's watchdog."""
    c.sh(f"sleep {SETTLE_S}")
    after = c.stats()
    st = _delta(before, after, "linux.stalls")
    o.detected_by = f"Linux: heartbeat still, stall after {after.get('linux.last_stall_cycles')} cycles" \
        if st else "not detected"
    o.cycles = str(after.get("linux.last_stall_cycles")) if st else "-"
    o.axes_stopped = "firmware restarted" if _delta(before, after, "linux.recoveries") else "no"


# Each takes the campaign and the outcome to fill; stats before the fault
# are taken by run_one, which also checks recovery and crashes after it.

def f_epoch(c: Campaign, o: Outcome, before: dict[str, str]) -> None:
    c.sh(f"devmem {c.word(OFF_SERVO_LINE + 4)} 32 0xdeadbeef")
    c.sh(f"sleep {SETTLE_S}")
    after = c.stats()
    n = c.log_count("servo line corrupt")
    o.detected_by = f"Linux: peer error on the next cycle, {_delta(before, after, 'linux.peer_errors')} such cycles; " \
        + ("crash reported" if c.report_crash else "stall on servod's record") \
        if n else "not detected"
    o.cycles = f"{c.wd_limit} (wd_limit) peer-error cycles" if n else "-"
    o.axes_stopped = "firmware restarted" if _delta(before, after, "linux.recoveries") else "no"


def f_state(c: Campaign, o: Outcome, before: dict[str, str]) -> None:
    c.sh(f"devmem {c.word(OFF_SERVO_LINE)} 32 0x12345678")
    c.sh(f"sleep {SETTLE_S}")
    after = c.stats()
    n = _delta(before, after, "linux.recoveries")
    o.detected_by = f"Linux: state word is no AMP_SSTATE_*, {_delta(before, after, 'linux.peer_errors')} peer-error cycles" \
        if _delta(before, after, "linux.peer_errors") else "not detected"
    o.cycles = f"{c.wd_limit} (wd_limit)" if n else "-"
    o.axes_stopped = "firmware restarted" if n else "no"


def f_fb_record(c: Campaign, o: Outcome, before: dict[str, str]) -> None:
    # n_axes of both feedback buffers, over and over for a while: the servo
    # rewrites a buffer every cycle, so a write lands between the servo's
    # write and Linux's read in some cycles only
    a0 = c.word(OFF_FB + 4 * FB_N_AXES_WORD)
    a1 = c.word(OFF_FB + FB_RECORD + 4 * FB_N_AXES_WORD)
    c.sh(f"i=0; while [ $i -lt 100 ]; do devmem {a0} 32 0xff; devmem {a1} 32 0xff; i=$((i+1)); done",
         timeout=120)
    c.sh("sleep 0.2")
    after = c.stats()
    inv = _delta(before, after, "linux.fb_invalid")
    o.detected_by = f"Linux: record refused (n_axes > AMP_MAX_AXES), fb_invalid +{inv}" if inv else "not detected"
    o.cycles = "same cycle" if inv else "-"
    o.axes_stopped = "not needed: the servo rewrites the buffer next cycle"


def f_mbox_length(c: Campaign, o: Outcome, before: dict[str, str]) -> None:
    # a request whose length is beyond the mailbox, handed to the servo
    c.sh(f"devmem {c.word(OFF_REQ + 4 * HDR_LENGTH_WORD)} 32 0xfffffff0 && "
         f"devmem {c.word(OFF_MBOX_SEM)} 32 {SEM_BUSY}")
    c.sh("sleep 0.1")
    sem = c.read_word(OFF_MBOX_SEM)
    status = c.read_word(OFF_RESP + 4 * HDR_STATUS_WORD)
    status = status - (1 << 32) if status & 0x80000000 else status
    get = c.sh("ampctl param get axes 2>&1")
    o.detected_by = (f"servo: frame check refused it, answered status {status}"
                     if sem == SEM_IDLE and status == AMP_E_PROTO else
                     f"servo: mailbox semaphore {sem}, answer status {status}")
    o.cycles = "next background poll"
    o.axes_stopped = "not needed"
    if "axes=" not in get:
        o.notes.append(f"next param get failed: {get.strip()}")


def f_cyc_sem(c: Campaign, o: Outcome, before: dict[str, str]) -> None:
    c.sh(f"devmem {c.word(OFF_CYC_SEM)} 32 0x5a5a5a5a")
    c.sh("sleep 0.5")
    after = c.stats()
    sem = c.read_word(OFF_CYC_SEM)
    o.detected_by = (f"Linux: semaphore neither idle nor busy, sem_corrupt +{_delta(before, after, 'linux.sem_corrupt')}"
                     if _delta(before, after, "linux.sem_corrupt") else "not detected")
    o.cycles = "same cycle" if _delta(before, after, "linux.sem_corrupt") else "-"
    o.axes_stopped = "not needed: the exchange goes on by sequence"
    if sem not in (SEM_IDLE, SEM_BUSY):
        o.notes.append(f"semaphore still 0x{sem:08x}")


def f_mbox_sem(c: Campaign, o: Outcome, before: dict[str, str]) -> None:
    c.sh(f"devmem {c.word(OFF_MBOX_SEM)} 32 0x5a5a5a5a")
    c.sh("sleep 0.1")
    get = c.sh("ampctl param get axes 2>&1")
    after = c.stats()
    o.detected_by = (f"Linux: mailbox semaphore neither idle nor busy, sem_corrupt +{_delta(before, after, 'linux.sem_corrupt')}"
                     if _delta(before, after, "linux.sem_corrupt") else "not detected")
    o.cycles = "next request"
    o.axes_stopped = "not needed"
    if "axes=" not in get:
        o.notes.append(f"param get after the fault: {get.strip()}")


def f_servo_irq_short(c: Campaign, o: Outcome, before: dict[str, str]) -> None:
    c.sh(irq_off(c.irq("servo_irq"), 3000))
    c.sh("sleep 0.3")
    after = c.stats()
    missed = _delta(before, after, "servo.missed")
    o.detected_by = (f"servo: {missed} cycles counted missed (TTC count)" if missed else "servo: nothing counted")
    o.cycles = "on the next interrupt"
    o.axes_stopped = f"no (below wd_limit={c.wd_limit}); stalls +{_delta(before, after, 'linux.stalls')}"


def f_servo_irq_long(c: Campaign, o: Outcome, before: dict[str, str]) -> None:
    c.sh(irq_off(c.irq("servo_irq")))
    _stall_seen(c, o, before)


def f_linux_irq(c: Campaign, o: Outcome, before: dict[str, str]) -> None:
    c.sh(irq_off(c.irq("linux_irq"), 50000))
    c.sh("sleep 0.5")
    after = c.stats()
    ss = _delta(before, after, "servo.safestops")
    o.detected_by = f"servo: Linux heartbeat still for wd_limit cycles, safe stop ({ss})" if ss else "servo: not detected"
    o.cycles = f"{c.wd_limit} (wd_limit)" if ss else "-"
    o.axes_stopped = "safe stop" if ss else "no"
    o.notes.append(f"servod missed {_delta(before, after, 'linux.missed_irq')} interrupts")


def f_hang(c: Campaign, o: Outcome, before: dict[str, str]) -> None:
    c.sh("ampctl debug hang")
    _stall_seen(c, o, before)


def f_irq_abort(c: Campaign, o: Outcome, before: dict[str, str]) -> None:
    """A data abort right after the firmware acknowledged its cycle
    interrupt: the restarted firmware must find its GIC CPU interface idle
    (before issue 20 item 5 the interrupt stayed active: CPU1's park loop
    never woke, and no start succeeded again)."""
    c.sh("ampctl debug irq-abort")
    _stall_seen(c, o, before)


@dataclass(frozen=True)
class Fault:
    name: str
    what: str
    run: Callable[[Campaign, Outcome, dict[str, str]], None]
    must_restart: bool      # the right answer is remoteproc's recovery
    # the right answer is a safe stop that holds the axes until the
    # operator's `ampctl resume` (SP_CMD_RESUME), the exchange running
    held: bool = False
    # the board's fault_injection entry it needs (servo_irq, linux_irq)
    needs: str = ""


FAULTS: list[Fault] = [
    Fault("epoch", "servo line's epoch word garbled (devmem), servo still beating", f_epoch, True),
    Fault("state", "servo state word garbled (no AMP_SSTATE_*)", f_state, True),
    Fault("fb-record", "feedback records' n_axes set to 255", f_fb_record, False),
    Fault("mbox-length", "mailbox request length 0xfffffff0 handed to the servo", f_mbox_length, False),
    Fault("cyc-sem", "cycle semaphore word garbled", f_cyc_sem, False),
    Fault("mbox-sem", "mailbox semaphore word garbled", f_mbox_sem, False),
    Fault("servo-irq-3ms", "servo's cycle interrupt disabled at the GIC for 3 ms", f_servo_irq_short, False,
          needs="servo_irq"),
    Fault("servo-irq-off", "servo's cycle interrupt disabled at the GIC for good", f_servo_irq_long, True,
          needs="servo_irq"),
    Fault("linux-irq-50ms", "Linux's cycle interrupt disabled at the GIC for 50 ms", f_linux_irq, False,
          held=True, needs="linux_irq"),
    Fault("hang", "firmware stops its cycle work and heartbeat (ampctl debug hang)", f_hang, True),
    Fault("irq-abort", "firmware aborts right after acknowledging its cycle interrupt (ampctl debug irq-abort)",
          f_irq_abort, True),
]


def run_one(c: Campaign, f: Fault) -> Outcome:
    o = Outcome(f.name, f.what)
    if f.needs and c.irqs.get(f.needs) is None:
        o.skipped = (f"{c.cb.board.name} has no {f.needs} in board.yaml fault_injection: "
                     + str((c.cb.board.data.get("fault_injection") or {}).get(f"{f.needs}_why", "not reachable from Linux")))
        return o
    ok, before = c.wait_attached_and_running()
    if not ok:
        o.notes.append("not running before the fault")
        return o
    f.run(c, o, before)
    held = ""
    if f.held:
        ok, _ = c.wait_attached_and_running(state="SAFESTOP")
        held = "exchange back at once, axes held in safe stop until `ampctl resume`" if ok \
            else "exchange NOT back"
        if ok:
            c.sh("ampctl resume 2>&1")
    ok, after = c.wait_attached_and_running()
    o.recovered = ok and (not f.held or not held.endswith("NOT back"))
    rec_n = _delta(before, after, "linux.recoveries")
    how = "remoteproc recovery" if c.report_crash else "servod's restart through remoteproc"
    o.recovery = held or ((f"{how} ({rec_n}), parameters restored" if rec_n else
                           "no restart needed") if ok else "NOT recovered")
    o.crashes = c.alive()
    detected = bool(o.detected_by) and not o.detected_by.endswith("not detected") and \
        "nothing counted" not in o.detected_by
    o.ok = detected and ok and o.crashes == 0 and (rec_n > 0) == f.must_restart and not \
        any(n.startswith(("next param get failed", "param get after", "semaphore still")) for n in o.notes)
    return o


def run_campaign(names: list[str] | None = None, *, board: netboard.ControllerBoard | None = None,
                 recording: Path | None = None, board_name: str = "zynq7000_qemu") -> dict[str, Any]:
    faults = [f for f in FAULTS if not names or f.name in names]
    unknown = set(names or []) - {f.name for f in FAULTS}
    if unknown:
        raise SystemExit(f"unknown fault(s): {', '.join(sorted(unknown))}; known: "
                         + ", ".join(f.name for f in FAULTS))
    own = board is None
    cb = board or netboard.ControllerBoard(qemu.Board.load(board_name))
    tmp = tempfile.TemporaryDirectory()
    mcap = recording or Path(tmp.name) / "faults.mcap"
    result: dict[str, Any] = {}
    try:
        if own:
            cb.start()
            cb.start_servod(SERVOD_ARGS)
            cb.start_firmware()
        ocm = cb.board.addr("servo", "mailbox", "base")
        camp = Campaign(cb, ocm, irqs=board_irqs(cb.board), report_crash=cb.has_report_crash())
        camp.wd_limit = int(cb.ampctl("param get wd_limit").split("=", 1)[1].split()[0])
        cb.wait_telemetry()
        stop = threading.Event()
        box: dict[str, Any] = {}

        def recorder() -> None:
            try:
                box["res"] = rec.record("127.0.0.1", cb.host_port, mcap, stop=stop, token=cb.token)
            except Exception as e:  # reported below
                box["err"] = e

        t = threading.Thread(target=recorder, daemon=True)
        t.start()
        cb.sh("sleep 0.5")
        outcomes = []
        for f in faults:
            o = run_one(camp, f)
            if o.skipped:
                print(f"[faults] {o.name}: skipped: {o.skipped}", flush=True)
            else:
                print(f"[faults] {o.name}: {'ok' if o.ok else 'FAILED'}: {o.detected_by}; {o.recovery}"
                      + (f"; {'; '.join(o.notes)}" if o.notes else ""), flush=True)
            outcomes.append(o)
        cb.sh("sleep 0.5")
        final = cb.stats()
        # let the drain thread hand over what is queued, then stop recording
        cb.sh("sleep 0.5")
        stop.set()
        t.join(30)
        if "err" in box:
            raise box["err"]
        s = info.summarize(mcap)
        span = int(s["last_cycle"]) - int(s["first_cycle"]) + 1 if s["cycles"] else 0
        lost = span - int(s["cycles"]) - int(s["lost_cycles"] or 0)
        data = {
            "recorded_cycles": s["cycles"], "span": span, "gaps": len(s["gaps"]),
            "declared_lost": s["lost_cycles"], "unaccounted": lost,
            "telem_dropped": int(final.get("telem.dropped", 0)),
        }
        result = {
            "faults": [asdict(o) for o in outcomes],
            "recording": data,
            "data_lost": lost + int(final.get("telem.dropped", 0)) + int(s["lost_cycles"] or 0),
            "wd_limit": camp.wd_limit,
            "board": cb.board.name,
            "clock": qemu.default_clock(),
            "date": time.strftime("%Y-%m-%d"),
        }
        result["ok"] = all(o.ok or o.skipped for o in outcomes) and result["data_lost"] == 0
    except BaseException:
        cb.mark_failed()
        raise
    finally:
        if own:
            cb.stop()
        tmp.cleanup()
    return result


def markdown(r: dict[str, Any]) -> str:
    rows = ["| fault | detected by | within | axes | recovered | crashes |",
            "|---|---|---|---|---|---|"]
    for o in r["faults"]:
        if o.get("skipped"):
            rows.append(f"| {o['fault']} | skipped: {o['skipped']} | - | - | - | - |")
            continue
        rows.append(f"| {o['fault']} | {o['detected_by']} | {o['cycles']} | {o['axes_stopped']} | "
                    f"{'yes: ' + o['recovery'] if o['recovered'] else 'NO'} | {o['crashes']} |")
    d = r["recording"]
    rows.append("")
    rows.append(f"Recording over the whole campaign: {d['recorded_cycles']} cycles of a span of "
                f"{d['span']}, {d['gaps']} declared gaps ({d['declared_lost']} cycles), "
                f"{d['unaccounted']} unaccounted, telemetry drops {d['telem_dropped']}: "
                f"data lost {r['data_lost']}. {r.get('board', '')}, wd_limit {r['wd_limit']}, "
                f"{r['clock']} clock, {r['date']}.")
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m servoamp.faults", description=__doc__.split("\n")[0])
    ap.add_argument("names", nargs="*", help="faults to run (default: all): "
                    + ", ".join(f.name for f in FAULTS))
    ap.add_argument("--json", type=Path, help="write the outcome as JSON")
    ap.add_argument("--markdown", action="store_true", help="print the docs/reliability.md table")
    ap.add_argument("--recording", type=Path, help="keep the campaign's MCAP here")
    ap.add_argument("--board", default="zynq7000_qemu", help="boards/NAME (default %(default)s)")
    a = ap.parse_args(argv)
    r = run_campaign(a.names or None, recording=a.recording, board_name=a.board)
    if a.json:
        a.json.parent.mkdir(parents=True, exist_ok=True)
        a.json.write_text(json.dumps(r, indent=1) + "\n")
    if a.markdown:
        print(markdown(r))
    print("[faults] " + ("every fault detected and recovered, no crash, no data lost" if r["ok"]
                         else "FAILED: see above"))
    return 0 if r["ok"] else 1


if __name__ == "__main__":
    sys.exit(main())
