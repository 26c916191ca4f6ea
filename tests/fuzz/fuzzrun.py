"""Build, seed and run the libFuzzer harnesses of tests/fuzz/.

Used by tests/fuzz/test_fuzz.py (a short run of each, plus the regression
inputs) and by scripts/fuzz.sh (the longer campaign):

    python tests/fuzz/fuzzrun.py campaign [--seconds N] [NAME...]

Seed corpora are made from real inputs into build/fuzz/seeds/<name>/: the
G-code programs of the repository, AUTH frames from the recorder's own
encoder (servoamp.telemetry), the test firmware images and the bad images
of tests/robot/fixtures (built here), the servo firmware if it was built,
and short programs of the OCM harness's operations. A campaign keeps its
growing corpus in build/fuzz/corpus/<name>/ and writes whatever it finds to
build/fuzz/findings/<name>/.
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import struct
import subprocess
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

FUZZ = Path(__file__).resolve().parent
TOP = FUZZ.parents[1]
BUILD = TOP / "build" / "fuzz"
NAMES = ("amp_ocm", "gcode", "telem_client", "rproc_check")
# The Python harness (Hypothesis) of the telemetry decoder, splitter and
# recorder session: tests/fuzz/fuzz_telemetry.py, run by the campaign too.
PY_NAMES = ("telemetry_py",)
REGRESSION = FUZZ / "regression"

# libFuzzer options per harness: the longest input worth trying (the
# telemetry harness needs room for more than 4096 bytes after the AUTH).
MAX_LEN = {"amp_ocm": 4096, "gcode": 4096, "telem_client": 12000, "rproc_check": 0}
COMMON = ["-timeout=10", "-rss_limit_mb=2048", "-print_final_stats=1"]


def binary(name: str) -> Path:
    return BUILD / f"fuzz_{name}"


def build(names: tuple[str, ...] = NAMES) -> None:
    subprocess.run(["make", "-s", "-C", str(FUZZ), *names], check=True)


# ---- seeds ---------------------------------------------------------------------

# Operation numbers of fuzz_amp_ocm.c (enum OP_*), in order.
(OP_WORD, OP_BYTES, OP_TAMPER, OP_FIX_HDR, OP_FIX_REQ, OP_FIX_RESP, OP_RECORD,
 OP_ANSWER, OP_L_INIT, OP_L_CYCLE, OP_L_POST, OP_L_POLL, OP_L_CALL, OP_L_PEER,
 OP_L_WD, OP_S_ATTACH, OP_S_RX, OP_S_TX, OP_S_POLL, OP_S_STATE) = range(20)


def _amp_seeds() -> dict[str, bytes]:
    """Programs of the OCM harness: the real exchange of both sides, then a
    few with the peer misbehaving."""
    u16 = struct.Struct("<H").pack
    u32 = struct.Struct("<I").pack
    cycle = bytes([OP_S_RX, 0, OP_S_TX, 8]) + u32(100) + u32(3) + bytes([OP_L_CYCLE, 8, 0])
    mbox = (bytes([OP_L_POST]) + u32(7) + u16(16) + bytes([OP_S_POLL]) + u16(24) + u32(0)
            + bytes([OP_L_POLL]) + u16(512))
    return {
        "linux-cycles": bytes([OP_L_CYCLE, 3, 0] * 4 + [OP_L_PEER]),
        "attach-exchange": bytes([OP_S_ATTACH, OP_L_CYCLE, 8, 0]) + cycle * 4,
        "mailbox": bytes([OP_S_ATTACH]) + mbox * 2,
        "mailbox-call-answered": bytes([OP_S_ATTACH, OP_L_POST]) + u32(1) + u16(4)
        + bytes([OP_ANSWER]) + u16(8) + u32(0) + bytes(range(8)) + bytes([OP_L_POLL]) + u16(64),
        "peer-records": bytes([OP_S_ATTACH, OP_RECORD, 1, 1, 8, OP_L_CYCLE, 1, 0,
                               OP_RECORD, 0, 3, 9, OP_S_RX, 0, OP_RECORD, 1, 0, 2, OP_L_CYCLE, 0, 0]),
        "reinit-reattach": bytes([OP_S_ATTACH]) + cycle + bytes([OP_L_INIT, 5, OP_S_RX, 0, OP_S_ATTACH])
        + cycle + bytes([OP_S_STATE]) + u32(0x53544C46) + u32(7) + bytes([OP_L_CYCLE, 1, 0] * 12),
        "tamper-answer": bytes([OP_S_ATTACH]) + bytes([OP_L_POST]) + u32(2) + u16(32) + bytes([OP_S_POLL])
        + u16(64) + u32(0) + bytes([OP_TAMPER, 12]) + u32(0xDEADBEEF) + bytes([OP_L_POLL]) + u16(512),
        "garbage-header": bytes([OP_WORD]) + u16(1) + u32(2) + bytes([OP_FIX_HDR, OP_S_ATTACH,
                                                                     OP_WORD]) + u16(4) + u32(64)
        + bytes([OP_S_ATTACH, OP_FIX_HDR, OP_S_ATTACH]),
    }


def _gcode_seeds() -> dict[str, bytes]:
    seeds = {p.name: p.read_bytes() for p in sorted((TOP / "examples").glob("*.nc"))}
    seeds.update({
        "features.nc": b"%\nN10 G21 G90 G17 (metric, absolute)\nG0 X1 Y2 Z3\nG1 X10 F600 ; feed\n"
                       b"G2 X20 Y2 I5 J0\nG3 X10 Y2 R5\nG2 X10 Y2 I5 P3\nG4 P0.5\nG92 X0 Y0\nG92.1\n"
                       b"G91 G1 X-1.5 Y.5\nG20 G90 G1 X1\nG18 G2 X0 Z0 I1 K0\nG19 G3 Y0 Z1 R.5\nM2\n%\n",
        "errors.nc": b"G1 X1\nG5\nG1 X1 X2 F10\nG2 X1 R0 F1\n(unclosed\nM3\nG1 X2000 F10\nG4\nN5 N6\n",
        "helix.nc": b"G1 F1200\nG17 G2 X0 Y0 Z5 I10 J0 P4\nM30\n",
    })
    return seeds


TELEM_TOKEN = b"fuzz-telemetry-token-0123456789ab"  # fuzz_telem_client.c's fz_token


def _chunks(data: bytes, *sizes: int) -> bytes:
    """The telemetry harness's framing: [n][n bytes] per chunk."""
    out, at = b"", 0
    for n in sizes:
        out += bytes([n]) + data[at:at + n]
        at += n
    while at < len(data):
        n = min(255, len(data) - at)
        out += bytes([n]) + data[at:at + n]
        at += n
    return out


def _telem_seeds() -> dict[str, bytes]:
    sys.path.insert(0, str(TOP / "python"))
    from servoamp import telemetry as tw  # the recorder's own encoder

    auth_tok, auth_open = tw.encode_auth(TELEM_TOKEN), tw.encode_auth(None)
    return {
        "auth-token": bytes([1]) + _chunks(auth_tok),
        "auth-token-split": bytes([1]) + _chunks(auth_tok, 3, 5, 1, 20),
        "auth-open": bytes([0]) + _chunks(auth_open),
        "auth-open-eof": bytes([2]) + _chunks(auth_open),
        "auth-then-flood": bytes([5]) + _chunks(auth_tok + b"x" * 300),
        "wrong-token": bytes([1]) + _chunks(tw.encode_auth(b"not-the-token")),
        "hello-instead": bytes([0]) + _chunks(struct.pack("<HHI", tw.MSG_HELLO, 0, 80) + bytes(80)),
    }


def _rproc_seeds() -> dict[str, bytes]:
    """The test firmware and the bad images the board suite uses (built from
    tests/robot/fixtures), and the servo firmware when it was built."""
    out = BUILD / "fixtures"
    subprocess.run(["make", "-s", "-C", str(TOP / "tests" / "robot" / "fixtures"), f"OUT={out}"],
                   check=True)
    seeds = {p.name: p.read_bytes() for p in sorted(out.glob("*.elf"))}
    for p in sorted((TOP / "build" / "rpu_app").glob("*/servo*.elf")):
        seeds[p.name] = p.read_bytes()
    return seeds


SEEDERS = {"amp_ocm": _amp_seeds, "gcode": _gcode_seeds, "telem_client": _telem_seeds,
           "rproc_check": _rproc_seeds}


def seeds(name: str) -> Path:
    d = BUILD / "seeds" / name
    if d.exists():
        shutil.rmtree(d)
    d.mkdir(parents=True)
    for fname, data in SEEDERS[name]().items():
        (d / fname).write_bytes(data)
    return d


# ---- runs ----------------------------------------------------------------------------

@dataclass
class Result:
    name: str
    seconds: float
    execs: int = 0
    exec_per_s: int = 0
    corpus: int = 0
    coverage: int = 0  # edges (libFuzzer "cov")
    features: int = 0  # libFuzzer "ft"
    findings: list[str] = field(default_factory=list)
    rc: int = 0
    log: str = ""


_STAT = re.compile(r"stat::(\w+):\s+(\d+)")
_COV = re.compile(r"cov: (\d+) ft: (\d+) corp: (\d+)/")


def run(name: str, corpus: Path, seed_dir: Path, findings: Path, *, seconds: int,
        runs: int = 0) -> Result:
    """One libFuzzer run from corpus (grown) and seed_dir (read only)."""
    findings.mkdir(parents=True, exist_ok=True)
    corpus.mkdir(parents=True, exist_ok=True)
    before = set(findings.iterdir())
    cmd = [str(binary(name)), *COMMON, f"-max_total_time={seconds}",
           f"-artifact_prefix={findings}/"]
    if runs:
        cmd.append(f"-runs={runs}")
    if MAX_LEN[name]:
        cmd.append(f"-max_len={MAX_LEN[name]}")
    cmd += [str(corpus), str(seed_dir)]
    t0 = time.monotonic()
    proc = subprocess.run(cmd, capture_output=True, text=True, errors="replace",
                          timeout=seconds + 300, cwd=BUILD)
    res = Result(name, round(time.monotonic() - t0, 1), rc=proc.returncode, log=proc.stderr)
    stats = dict((k, int(v)) for k, v in _STAT.findall(proc.stderr))
    res.execs = stats.get("number_of_executed_units", 0)
    res.exec_per_s = stats.get("average_exec_per_sec", 0)
    cov = _COV.findall(proc.stderr)
    if cov:
        res.coverage, res.features, res.corpus = (int(x) for x in cov[-1])
    res.findings = sorted(p.name for p in set(findings.iterdir()) - before)
    return res


def replay(name: str) -> subprocess.CompletedProcess[str]:
    """Every regression input of a harness, once."""
    files = sorted(p for p in (REGRESSION / name).glob("*") if p.is_file())
    return subprocess.run([str(binary(name)), *map(str, files)], capture_output=True, text=True,
                          errors="replace", timeout=300)


_PY_LINE = re.compile(r"telemetry fuzz (\w+): (\d+) executions in (\d+) s \((\d+)/s\), (\d+) findings")


def run_python(seconds: int) -> Result:
    """tests/fuzz/fuzz_telemetry.py for `seconds` in all (its three targets)."""
    t0 = time.monotonic()
    p = subprocess.run([sys.executable, str(FUZZ / "fuzz_telemetry.py"), "--seconds", str(seconds)],
                       capture_output=True, text=True, errors="replace", timeout=seconds * 3 + 300)
    res = Result("telemetry_py", time.monotonic() - t0, rc=p.returncode, log=p.stdout + p.stderr)
    for m in _PY_LINE.finditer(p.stdout):
        res.execs += int(m.group(2))
        if int(m.group(5)):
            res.findings.append(f"{m.group(1)}: {m.group(5)}")
    res.exec_per_s = int(res.execs / res.seconds) if res.seconds else 0
    if p.returncode and not res.findings:
        res.findings.append(f"exit {p.returncode}")
    if res.findings:  # the shrunk inputs and what they raised, as the harness printed them
        print(p.stdout[-6000:], file=sys.stderr)
    return res


def campaign(seconds: int, names: tuple[str, ...]) -> list[Result]:
    results = []
    for name in names:
        if name in PY_NAMES:
            results.append(run_python(seconds))
            print(f"{name}: {results[-1].execs} executions in {results[-1].seconds:.0f} s, "
                  f"{len(results[-1].findings)} findings", file=sys.stderr, flush=True)
    names = tuple(n for n in names if n not in PY_NAMES)
    if names:
        build(names)
    for name in names:  # one at a time: the machine is shared
        res = run(name, BUILD / "corpus" / name, seeds(name), BUILD / "findings" / name,
                  seconds=seconds)
        results.append(res)
        print(f"{name}: {res.execs} executions in {res.seconds} s, "
              f"{len(res.findings)} findings", file=sys.stderr, flush=True)
    return results


def table(results: list[Result]) -> str:
    rows = [("harness", "seconds", "executions", "exec/s", "corpus", "coverage (edges)",
             "features", "findings")]
    for r in results:
        rows.append((r.name, f"{r.seconds:.0f}", str(r.execs), str(r.exec_per_s), str(r.corpus),
                     str(r.coverage), str(r.features),
                     str(len(r.findings)) + (f" ({', '.join(r.findings)})" if r.findings else "")))
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    lines = ["| " + " | ".join(c.ljust(w) for c, w in zip(row, widths)) + " |" for row in rows]
    lines.insert(1, "|" + "|".join("-" * (w + 2) for w in widths) + "|")
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="scripts/fuzz.sh", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("campaign", help="run the harnesses one after the other")
    c.add_argument("--seconds", type=int, default=300, help="per harness (default 300)")
    c.add_argument("names", nargs="*", metavar="NAME",
                   help=f"harnesses (default all: {' '.join(NAMES + PY_NAMES)})")
    args = ap.parse_args(argv)
    known = NAMES + PY_NAMES
    unknown = [n for n in args.names if n not in known]
    if unknown:
        ap.error(f"unknown harness {', '.join(unknown)} (known: {' '.join(known)})")
    names = tuple(args.names) or known
    results = campaign(args.seconds, names)
    print(table(results))
    out = BUILD / "campaign.json"
    out.write_text(json.dumps([{k: v for k, v in asdict(r).items() if k != "log"}
                               for r in results], indent=1))
    print(f"(figures also in {out.relative_to(TOP)}; findings in build/fuzz/findings/<name>/)")
    return 1 if any(r.findings or r.rc != 0 for r in results) else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
