# SPDX-License-Identifier: MIT
"""servoamp's benchmarks behind one entry point, and their summary table.

    scripts/bench.sh [NAME...]          # run (all when no NAME), then the table
    scripts/bench.sh -b zynqmp_qemu     # the board benchmarks on that board only
    scripts/bench.sh --list [-b NAME]   # what exists, on which board, how long each takes
    scripts/bench.sh --table [NAME...]  # only the table, from bench/results
    scripts/bench.sh --quick [NAME...]  # tiny configurations into build/bench/quick
    west bench ...                      # the same

Boards: a host benchmark runs once; a board benchmark once per board it
has been ported to (every board under boards/ by default, -b/--board NAME,
repeatable, to choose). One that cannot run on a chosen board yet is
skipped with the reason (--list gives it too).

Each benchmark writes bench/results/<name>.json (a host benchmark, or a
board benchmark on zynq7000_qemu, the first board) or
bench/results/<name>-<board>.json (a board benchmark on another board;
results_stem). Targets: bench/targets.toml's [<name>] table holds the
design's targets for every board; a [<name>-<board>] table, when there is
one, comes first for that board. Every results file carries
a "figures" list (bench/figures.schema.json); the table shows each figure
against its target from bench/targets.toml (or the figure's own "target"),
with the ratio value/target and pass/fail. A results file that no
benchmark here writes (another tool's) is shown all the same.

Exit status: 1 if a benchmark failed to run or a results file does not
match the schema; a missed target is reported, not an error.
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import math
import os
import subprocess
import sys
import time
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import jsonschema

REPO = Path(__file__).resolve().parents[2]
SCHEMA = REPO / "bench" / "figures.schema.json"
TARGETS = REPO / "bench" / "targets.toml"
RESULTS = REPO / "bench" / "results"
QUICK_RESULTS = REPO / "build" / "bench" / "quick"
LOGS = REPO / "build" / "bench"


@dataclass(frozen=True)
class Bench:
    name: str
    what: str
    board: bool                  # boots the emulated board (QEMU)
    duration: str                # measured on the project's 2-core host
    build: tuple[tuple[str, ...], ...]
    run: tuple[str, ...]         # {python} and {json} are substituted
    quick: tuple[str, ...]       # extra arguments for --quick
    needs: str = ""              # a file that must exist (optional benchmarks)
    # a board benchmark: the boards it runs on ({board} in run is the
    # board's name), and why it cannot run on the others yet
    boards: tuple[str, ...] = ()
    not_yet: str = ""

    def command(self, json_path: Path, quick: bool, board: str | None = None) -> list[str]:
        args = [a.format(python=sys.executable, json=str(json_path), board=board or "") for a in self.run]
        return args + (list(self.quick) if quick else [])

    def why_not(self, board: str) -> str | None:
        """None if this board benchmark runs on ``board``, else the reason."""
        if board in self.boards:
            return None
        return self.not_yet or f"not ported to {board}"


BENCHMARKS: dict[str, Bench] = {b.name: b for b in (
    Bench("transport", "amp_lib exchange vs cache-line floor (alternating blocks), mailbox 16 and 512 B "
          "(and their ratio), eventfd, pipe",
          False, "1-2 min (eventfd, pipe and the mailbox dominate; 5 min with stress-ng)",
          (("make", "-s", "-C", "amp_lib", "bench"),),
          ("build/amp_lib/none/transport_bench", "--iters", "200000", "--blocks", "20", "--json", "{json}"),
          ("--iters", "2000", "--blocks", "4")),
    Bench("footprint", "servo-side amp_lib code and data size (arm-none-eabi-gcc -Os)",
          False, "about 5 s",
          (),
          ("{python}", "bench/amp_footprint.py", "--json", "{json}"),
          ()),
    Bench("motion", "G-code pipeline: one-thread throughput, hybrid scheduler speed-up on 2 workers",
          False, "about 50 s quiet, about 2 min on a busy host",
          (("make", "-s", "-C", "motion", "-j2", "host"),),
          ("build/motion/host/motion_bench", "--json", "{json}"),
          ("--blocks", "300", "--arcs", "200", "--reps", "1", "--chord", "1")),
    Bench("cycle", "the cycle on the emulated board under virtual time: missed cycles, costs, latencies; "
          "cost per axis (1..8 axes at 1 and 4 kHz), the highest rate per axis count, 100,000 cycles at 4 kHz",
          True, "about 3-4 min per board (one QEMU boot each, about 70 s of guest time; zynqmp_qemu: 141 s on a busy host)",
          (),
          ("{python}", "bench/cycle/cycle_bench.py", "--board", "{board}", "--json", "{json}"),
          ("--seconds", "1", "--short", "0.5", "--sweep-axes", "1,8", "--sweep-rates", "1000,4000,8000",
           "--window-cycles", "300", "--long-cycles", "2000"),
          boards=("zynq7000_qemu", "zynqmp_qemu")),
    Bench("determinism", "the same recorded scenario on a quiet and a loaded host (virtual time)",
          True, "about 1.5 min (three QEMU boots, 8000 cycles recorded each)",
          (),
          ("{python}", "bench/cycle/determinism_bench.py", "--json", "{json}"),
          ("--cycles", "300", "--runs", "quiet"),
          boards=("zynq7000_qemu",),
          not_yet="not yet: determinism_bench.py boots zynq7000_qemu only (the board is fixed in the script)"),
    Bench("fieldbus", "CiA 402 drives on CAN (firmware in QEMU, drive simulators in lockstep): "
          "bus load per cycle, highest drives x rate per bus with 0 SYNC missed",
          True, "about 3 min (4 QEMU boots; the first run builds the firmware variants)",
          (),
          ("{python}", "bench/fieldbus/can_bench.py", "--json", "{json}"),
          ("--quick",),
          boards=("zynq7000_qemu",),
          not_yet="not yet: can_bench.py builds its firmware from overlays of boards/zynq7000_qemu/"
                  "servo.dts only (the board is fixed in the script; the ZynqMP's CAN: issue 35 item 4)"),
    Bench("rt_latency", "servod's wake-up and cyclictest on the board's kernels (zynq7000_qemu: vanilla and "
          "PREEMPT_RT; zynqmp_qemu: PREEMPT_RT) at 1 and 4 kHz, idle and under hackbench, a CPU hog, bulk TCP "
          "and a recovery (virtual time)",
          True, "at 10,000 cycles per window: about 20 min on zynq7000_qemu (two kernel boots, 20 windows; "
                "100,000: about 4.7 h of one core, --jobs 2 --resume), about 23 min on zynqmp_qemu (one boot, "
                "10 windows; measured with a load average of 10-12)",
          (),
          ("{python}", "bench/cycle/rt_latency_bench.py", "--board", "{board}", "--json", "{json}"),
          ("--cycles", "500", "--loads", "idle,cpu"),
          boards=("zynq7000_qemu", "zynqmp_qemu")),
    Bench("recorder", "recording encodings, JSON (servoamp record) vs protobuf (servoamp bridge, foxglove-sdk): "
          "bytes/cycle, CPU per 1000 cycles, max rate x axes at 4 and 8 axes",
          False, "about 2-3 min (one rate ramp per encoding and axis count)",
          (),
          ("{python}", "bench/recorder/encoding_bench.py", "--json", "{json}"),
          ("--quick",),
          needs="bench/recorder/encoding_bench.py"),
)}


# ---- results and targets ------------------------------------------------

FIRST_BOARD = "zynq7000_qemu"   # the board every board benchmark ran on first


BOARDS = REPO / "boards"


def known_boards(root: Path = BOARDS) -> list[str]:
    """Every board folder (boards/<name>/board.yaml), the first board first."""
    names = sorted(p.parent.name for p in root.glob("*/board.yaml"))
    return sorted(names, key=lambda n: n != FIRST_BOARD)


def results_stem(name: str, board: str | None) -> str:
    """The results file's stem of benchmark ``name`` on ``board``: the
    name alone for a host benchmark and for the first board (the files
    from before there were two keep their names), ``<name>-<board>`` for
    any other board (bench/results/cycle-zynqmp_qemu.json)."""
    return name if board in (None, FIRST_BOARD) else f"{name}-{board}"


@dataclass
class Target:
    value: float
    better: str | None
    source: str


def load_targets(path: Path = TARGETS) -> dict[str, dict[str, Target]]:
    """bench/targets.toml as {file stem: {figure name or pattern: Target}}."""
    raw = tomllib.loads(path.read_text())
    out: dict[str, dict[str, Target]] = {}
    for stem, figs in raw.items():
        if not isinstance(figs, dict):
            raise ValueError(f"{path}: [{stem}] must be a table of figures")
        for name, t in figs.items():
            if not isinstance(t, dict) or not isinstance(t.get("target"), (int, float)) \
                    or not isinstance(t.get("source"), str) or not t["source"].strip() \
                    or t.get("better", "lower") not in ("lower", "higher") \
                    or set(t) - {"target", "better", "source"}:
                raise ValueError(f"{path}: [{stem}.\"{name}\"] needs a numeric target, a source "
                                 f"and optionally better = lower|higher, nothing else")
            out.setdefault(stem, {})[name] = Target(float(t["target"]), t.get("better"), t["source"])
    return out


def find_target(targets: dict[str, dict[str, Target]], stem: str, name: str,
                bench: str | None = None) -> Target | None:
    """The target of figure ``name`` in results file ``stem``: from the
    file's own table ([cycle-zynqmp_qemu]) first, then from its benchmark's
    ([cycle]: the design's targets, for every board)."""
    for table in dict.fromkeys((stem, bench or stem)):
        figs = targets.get(table, {})
        if name in figs:
            return figs[name]
        for pattern, t in figs.items():
            if fnmatch.fnmatchcase(name, pattern):
                return t
    return None


def validate(doc: Any) -> list[str]:
    """Schema errors of one results document, plus duplicate names."""
    schema = json.loads(SCHEMA.read_text())
    errors = [f"{'/'.join(str(p) for p in e.absolute_path) or '(top)'}: {e.message}"
              for e in jsonschema.Draft202012Validator(schema).iter_errors(doc)]
    if not errors:
        names = [f["name"] for f in doc["figures"]]
        errors += [f"figures: duplicate name {n!r}" for n in sorted({n for n in names if names.count(n) > 1})]
        errors += [f"figures/{f['name']}: value is not finite" for f in doc["figures"]
                   if not math.isfinite(f["value"])]
    return errors


@dataclass
class Row:
    bench: str
    name: str
    value: float | None
    unit: str
    better: str
    target: float | None
    source: str | None
    spread: dict[str, float] | None
    note: str
    board: str = "host"

    @property
    def status(self) -> str:
        if self.value is None:
            return "error"
        if self.target is None:
            return ""
        ok = self.value <= self.target if self.better == "lower" else self.value >= self.target
        return "pass" if ok else "FAIL"

    @property
    def ratio(self) -> float | None:
        if self.value is None or self.target is None or self.target == 0:
            return None
        return self.value / self.target


def split_stem(stem: str, boards: list[str]) -> tuple[str, str]:
    """A results file's stem -> (benchmark, board): ``cycle-zynqmp_qemu``
    -> (cycle, zynqmp_qemu); a board benchmark's plain stem is its first
    board's; anything else is "host"."""
    for b in boards:
        if stem.endswith(f"-{b}") and stem != f"-{b}":
            return stem[:-len(b) - 1], b
    bench = BENCHMARKS.get(stem)
    return stem, (FIRST_BOARD if bench is not None and bench.board else "host")


def rows_of(stem: str, path: Path, targets: dict[str, dict[str, Target]],
            boards: list[str] | None = None) -> list[Row]:
    name, board = split_stem(stem, known_boards() if boards is None else boards)
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError) as e:
        return [Row(name, "(unreadable)", None, "", "lower", None, None, None, str(e), board)]
    errors = validate(doc)
    if errors:
        return [Row(name, "(schema)", None, "", "lower", None, None, None, e, board) for e in errors]
    if isinstance(doc.get("board"), str):
        board = doc["board"]
    rows = []
    for f in doc["figures"]:
        t = find_target(targets, stem, f["name"], name)
        rows.append(Row(name, f["name"], float(f["value"]), f["unit"],
                        (t.better if t and t.better else f["better"]),
                        t.value if t else f.get("target"),
                        t.source if t else f.get("target_source", "results file" if "target" in f else None),
                        f.get("spread"), f.get("note", ""), board))
    return rows


def fmt(v: float | None) -> str:
    if v is None:
        return "-"
    if v == int(v) and abs(v) < 1e15:
        return f"{int(v):,}" if abs(v) >= 10000 else str(int(v))
    a = abs(v)
    if a >= 10000:
        return f"{v:,.0f}"
    if a >= 100:
        return f"{v:.0f}"
    if a >= 10:
        return f"{v:.1f}"
    if a >= 1:
        return f"{v:.2f}"
    return f"{v:.3g}"


def table(rows: list[Row]) -> str:
    sources: list[str] = []
    lines = []
    head = ("bench", "board", "figure", "value", "unit", "target", "ratio", "status", "spread / note")
    cells = []
    for r in rows:
        tgt = "-"
        if r.target is not None:
            if r.source not in sources:
                sources.append(r.source or "")
            tgt = f"{'<=' if r.better == 'lower' else '>='} {fmt(r.target)} [{sources.index(r.source or '') + 1}]"
        spread = ""
        if r.spread:
            lo, hi = r.spread.get("min"), r.spread.get("max")
            q1, q3 = r.spread.get("q1"), r.spread.get("q3")
            parts = []
            if q1 is not None and q3 is not None:
                parts.append(f"IQR {fmt(q1)}-{fmt(q3)}")
            if lo is not None and hi is not None:
                parts.append(f"min-max {fmt(lo)}-{fmt(hi)}")
            spread = ", ".join(parts)
        note = "; ".join(p for p in (spread, r.note) if p)
        cells.append((r.bench, r.board, r.name, fmt(r.value), r.unit, tgt,
                      "-" if r.ratio is None else f"{r.ratio:.2f}", r.status, note))
    widths = [max(len(c[i]) for c in [head, *cells]) for i in range(len(head) - 1)]
    for c in [head, *cells]:
        lines.append("  ".join(s.ljust(w) if i in (0, 1, 2, 4, 5, 7) else s.rjust(w)
                               for i, (s, w) in enumerate(zip(c[:-1], widths))) + "  " + c[-1])
    lines.insert(1, "-" * max(len(l) for l in lines))
    met = sum(r.status == "pass" for r in rows)
    failed = sum(r.status == "FAIL" for r in rows)
    lines.append("")
    lines.append(f"{met} of {met + failed} targets met" +
                 (f", {sum(r.status == 'error' for r in rows)} errors" if any(r.status == "error" for r in rows)
                  else ""))
    for i, s in enumerate(sources, 1):
        lines.append(f"[{i}] {s}")
    return "\n".join(lines)


def result_files(results: Path, names: list[str], boards: list[str] | None = None,
                 known: list[str] | None = None) -> list[tuple[str, Path]]:
    """The results files of the table, as (stem, path): those of ``names``
    (every file when empty), a board benchmark's only on ``boards`` (all
    when None); in BENCHMARKS' order, each benchmark's boards in order."""
    known = known_boards() if known is None else known
    found = {p.stem: p for p in sorted(results.glob("*.json"))}
    out = []
    for stem, path in found.items():
        name, board = split_stem(stem, known)
        if names and name not in names and stem not in names:
            continue
        if boards is not None and board != "host" and board not in boards:
            continue
        out.append((stem, path))
    order = list(BENCHMARKS)

    def key(item: tuple[str, Path]) -> tuple[int, str, int]:
        name, board = split_stem(item[0], known)
        return (order.index(name) if name in order else len(order), name,
                known.index(board) if board in known else -1)
    return sorted(out, key=key)


# ---- running ----------------------------------------------------------------

def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return "?"


def _caches() -> dict[str, str]:
    """cpu0's caches as the kernel lists them: {"L1d": "32K", "L2": "1024K", ...}."""
    out: dict[str, str] = {}
    for d in sorted(Path("/sys/devices/system/cpu/cpu0/cache").glob("index*")):
        try:
            level = (d / "level").read_text().strip()
            kind = (d / "type").read_text().strip()
            size = (d / "size").read_text().strip()
        except OSError:
            continue
        if kind == "Instruction":
            continue
        out[f"L{level}{'d' if kind == 'Data' else ''}"] = size
    return out


def host_info() -> dict[str, Any]:
    """What a results file is worth only together with: the machine it was
    measured on (the ratios against a floor move with the CPU and its
    caches: docs/amp-figures.md), and how busy it was at the end."""
    return {"cpu": _cpu_model(), "cpus_online": os.cpu_count() or 0, "cache_cpu0": _caches(),
            "kernel": os.uname().release, "loadavg_at_end": list(os.getloadavg()),
            "utc_at_end": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}


def stamp_host(path: Path) -> None:
    """Adds "measured_on" (host_info()) to a results file a benchmark just wrote."""
    doc = json.loads(path.read_text())
    if isinstance(doc, dict):
        doc["measured_on"] = host_info()
        path.write_text(json.dumps(doc, indent=1) + "\n")


def run_bench(b: Bench, results: Path, quick: bool, verbose: bool, board: str | None = None) -> tuple[bool, str]:
    if b.needs and not (REPO / b.needs).exists():
        return True, f"skipped: {b.needs} does not exist yet"
    stem = results_stem(b.name, board)
    LOGS.mkdir(parents=True, exist_ok=True)
    log = LOGS / f"{stem}{'-quick' if quick else ''}.log"
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO / "python"), env.get("PYTHONPATH", "")) if p)
    results.mkdir(parents=True, exist_ok=True)
    out = results / f"{stem}.json"
    t0 = time.monotonic()
    with log.open("w") as lf:
        for cmd in (*b.build, tuple(b.command(out, quick, board))):
            lf.write(f"$ {' '.join(cmd)}\n")
            lf.flush()
            if verbose:
                print(f"[bench] $ {' '.join(cmd)}", flush=True)
                p = subprocess.Popen(cmd, cwd=REPO, env=env, stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True)
                assert p.stdout is not None
                for line in p.stdout:
                    sys.stdout.write(line)
                    lf.write(line)
                rc = p.wait()
            else:
                rc = subprocess.call(cmd, cwd=REPO, env=env, stdout=lf, stderr=subprocess.STDOUT)
            if rc:
                return False, f"failed (exit {rc}) after {time.monotonic() - t0:.0f} s: see {log}"
    try:
        stamp_host(out)
    except (OSError, ValueError) as e:
        return False, f"{out}: not a results file ({e})"
    return True, f"{time.monotonic() - t0:.0f} s, wrote {out.relative_to(REPO) if out.is_relative_to(REPO) else out}"


def needs_board(names: list[str]) -> bool:
    return any(BENCHMARKS[n].board for n in (names or list(BENCHMARKS)) if n in BENCHMARKS)


def plan(names: list[str], boards: list[str]) -> list[tuple[Bench, str | None, str | None]]:
    """What a run does, in order: (benchmark, board or None for a host
    benchmark, None to run or the reason it is skipped)."""
    out: list[tuple[Bench, str | None, str | None]] = []
    for n in names or list(BENCHMARKS):
        b = BENCHMARKS[n]
        if not b.board:
            out.append((b, None, None))
            continue
        out += [(b, board, b.why_not(board)) for board in boards]
    return out


def list_text(boards: list[str]) -> str:
    """--list: each benchmark, host or board, how long, and on each board
    whether it runs there (and why not)."""
    lines = []
    for b in BENCHMARKS.values():
        state = "" if not b.needs or (REPO / b.needs).exists() else f" (not present: {b.needs})"
        lines.append(f"{b.name:<12} {'board' if b.board else 'host':<5} {b.duration}{state}")
        lines.append(f"{'':<12} {b.what}")
        if b.board:
            for board in boards:
                why = b.why_not(board)
                lines.append(f"{'':<12} on {board}: " + (f"runs ({results_stem(b.name, board)}.json)"
                                                         if why is None else f"skipped: {why}"))
        lines.append(f"{'':<12} $ {' '.join(b.run)}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="bench", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("names", nargs="*", metavar="NAME", help="benchmarks to run (default: all); see --list")
    ap.add_argument("-b", "--board", action="append", metavar="BOARD", dest="boards",
                    help="run the board benchmarks on this board (repeatable; default: every board under "
                         "boards/); host benchmarks run once whatever the boards")
    ap.add_argument("--list", action="store_true", help="list the benchmarks and exit")
    ap.add_argument("--table", action="store_true", help="run nothing: the table of the results there are")
    ap.add_argument("--quick", action="store_true",
                    help="tiny configurations (a smoke run; figures meaningless) into build/bench/quick")
    ap.add_argument("--results", type=Path, help="results directory (default: bench/results, "
                                                  "build/bench/quick with --quick)")
    ap.add_argument("-v", "--verbose", action="store_true", help="show the benchmarks' own output")
    ap.add_argument("--scope", action="store_true", help=argparse.SUPPRESS)  # for scripts/bench.sh
    args = ap.parse_args(argv)
    known = known_boards()
    bad = [b for b in args.boards or [] if b not in known]
    if bad:
        ap.error(f"unknown board {', '.join(bad)} (boards: {', '.join(known)}; each a folder boards/NAME "
                 "with a board.yaml)")
    boards = list(dict.fromkeys(args.boards)) if args.boards else known

    if args.scope:  # which bootstrap the selection needs
        print("all" if not (args.list or args.table) and needs_board(args.names) else "host")
        return 0
    if args.list:
        print(list_text(boards))
        return 0
    results = args.results or (QUICK_RESULTS if args.quick else RESULTS)
    results = results if results.is_absolute() else Path.cwd() / results
    unknown = [n for n in args.names if n not in BENCHMARKS and not (results / f"{n}.json").exists()]
    if unknown:
        ap.error(f"unknown benchmark {', '.join(unknown)} (known: {', '.join(BENCHMARKS)})")
    rc = 0
    if not args.table:
        for n in args.names:
            if n not in BENCHMARKS:
                print(f"[bench] {n}: no runner here; showing {results / (n + '.json')}")
        selected = [n for n in args.names if n in BENCHMARKS]
        for b, board, why in plan(selected, boards) if selected or not args.names else []:
            tag = b.name if board is None else f"{b.name} on {board}"
            if why is not None:
                print(f"[bench] {tag}: skipped: {why}", flush=True)
                continue
            print(f"[bench] {tag}: running ({b.duration}{', boots QEMU' if b.board else ''})", flush=True)
            ok, msg = run_bench(b, results, args.quick, args.verbose, board)
            print(f"[bench] {tag}: {msg}", flush=True)
            rc |= 0 if ok else 1
    try:
        targets = load_targets()
    except (OSError, ValueError) as e:
        print(f"[bench] {e}", file=sys.stderr)
        return 1
    rows = [r for stem, path in result_files(results, args.names, boards if args.boards else None, known)
            for r in rows_of(stem, path, targets, known)]
    print()
    print(f"results: {results}" + ("  (--quick: smoke-run sizes, the figures mean nothing)" if args.quick else ""))
    print(table(rows))
    if any(r.status == "error" for r in rows):
        rc = 1
    return rc


if __name__ == "__main__":
    sys.exit(main())
