"""Issue 20, item 7b: amp_lib's handshake model-checked with Spin.

tests/model/amp_handshake.pml models the two cores' steps of amp_lib
(amp_linux.c, amp_servo.c, amp_common.c, as rpu_app/src/link.c and servod
drive them), a crash and re-attach of either side at any step and a stray
write to any control word (docs/amp-protocol.md section 9 maps the model to
the code). Spin generates the verifier (pan), gcc compiles it, and pan's
exhaustive search must find no violation of FRESH (nothing stale or torn
taken as fresh), ACK (no command acknowledged but lost), RESUME (no
deadlock: the link resumes or reports an error servod recovers) nor an
invalid end state, and must have searched everything (no depth or memory
bound hit). Each MUTANT_* puts back one weakness (the code before this
item's fixes, or a safeguard removed): Spin must find its violation, so the
check can fail.

The searches run two at a time (a thread pool over the pan processes); on a
2-core machine the whole module takes 20-40 s (about 36 s of CPU; the largest
check, ~20 s, is the critical path).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import time
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import pytest

MODEL = Path(__file__).with_name("amp_handshake.pml")

pytestmark = pytest.mark.skipif(
    shutil.which("spin") is None or shutil.which("gcc") is None,
    reason="spin or gcc not installed (Debian: apt-get install spin gcc; scripts/bootstrap.sh does)",
)

# The exhaustive checks. The periodic exchange and the mailbox share no word,
# so each is checked on its own (NO_MBOX / NO_PERIODIC). A Linux crash
# restarts both sides on a zeroed region (amp_linux_init's contract: the
# servo is offline), leaving nothing but the header's epoch behind, so it is
# checked apart from the servo crash and the stray write (docs section 9).
CHECKS: dict[str, list[str]] = {
    "periodic: servo crash + stray write": ["-DNO_MBOX", "-DMAXLC=0", "-DMAXSC=1", "-DMAXCOR=1"],
    "periodic: Linux crash": ["-DNO_MBOX", "-DMAXLC=1", "-DMAXSC=0", "-DMAXCOR=0"],
    "mailbox: servo crash + stray write": ["-DNO_PERIODIC", "-DMAXLC=0", "-DMAXSC=1", "-DMAXCOR=1"],
    "mailbox: Linux crash": ["-DNO_PERIODIC", "-DMAXLC=1", "-DMAXSC=0", "-DMAXCOR=0"],
}

# A check that stores fewer states than this has not explored the model (it
# stopped, or the model blocks early): each run above stores far more.
MIN_STATES = 100_000

# Each mutant, the fault configuration that exposes it fastest, and the
# assertion Spin must report (the property it breaks).
WHOLE = "gwhole"                                        # FRESH: a torn copy taken
NEW = "gnew"                                            # FRESH: an old record taken again
ACK = "((ack==0)||((ack<31)&&((g_taken>>ack)&1)))"      # ACK
RESUME = "((ok_rt&&ok_mb)||err)"                        # RESUME

MUTANTS: dict[str, tuple[list[str], str]] = {
    # safeguards of the code at HEAD before this item, removed
    "NO_BEGIN": (["-DNO_MBOX", "-DMAXLC=0", "-DMAXSC=0"], WHOLE),
    "NO_EPOCH": (["-DNO_MBOX", "-DMAXSC=0", "-DMAXCOR=0"], NEW),
    "NO_CMD_RESYNC": (["-DNO_MBOX", "-DMAXLC=0"], RESUME),
    "NO_SEM_REPAIR": (["-DNO_PERIODIC", "-DMAXLC=0", "-DMAXSC=0"], RESUME),
    # the code as it was before this item's fixes
    "NO_DUP": (["-DNO_MBOX", "-DMAXLC=0", "-DMAXSC=0", "-DMAXCOR=0"], NEW),
    "ACK_ATTACH": (["-DNO_MBOX", "-DMAXLC=0", "-DMAXCOR=0", "-DNL=2"], ACK),
    "NO_SKIP": (["-DNO_MBOX", "-DMAXLC=0"], WHOLE),
    "NO_REASSERT": (["-DNO_PERIODIC", "-DMAXLC=0", "-DMAXSC=0"], RESUME),
    "PEER_ABSENT": (["-DNO_MBOX", "-DMAXLC=0", "-DMAXSC=0"], RESUME),
}


@dataclass
class Search:
    name: str
    out: str
    returncode: int
    errors: int
    states: int
    depth: int
    seconds: float
    violated: str

    @property
    def truncated(self) -> bool:
        return ("search depth too small" in self.out or "max search depth too small" in self.out
                or "out of memory" in self.out.lower() or "hash table is full" in self.out)


def _field(pattern: str, out: str) -> int:
    m = re.search(pattern, out)
    return int(m.group(1)) if m else -1


def _search(name: str, defines: list[str], workdir: Path, optimise: str, extra_cc: list[str]) -> Search:
    """spin -a, gcc, ./pan in a directory of its own."""
    workdir.mkdir(parents=True)
    shutil.copy(MODEL, workdir / MODEL.name)
    t0 = time.monotonic()
    subprocess.run(["spin", *defines, "-a", MODEL.name], cwd=workdir, check=True,
                   capture_output=True, text=True, timeout=120)
    subprocess.run(["gcc", optimise, "-DSAFETY", *extra_cc, "-o", "pan", "pan.c"], cwd=workdir,
                   check=True, capture_output=True, text=True, timeout=300)
    # -m: depth bound far above the model's (a few hundred steps); -w24:
    # 16 M hash slots for at most ~10 M states
    proc = subprocess.run(["./pan", "-m20000", "-w24"], cwd=workdir, capture_output=True,
                          text=True, timeout=600)
    out = proc.stdout + proc.stderr
    m = re.search(r"pan:\d+: (assertion violated .*?) \(at depth", out)
    return Search(name=name, out=out, returncode=proc.returncode,
                  errors=_field(r"errors: (\d+)", out),
                  states=_field(r"(\d+) states, stored", out),
                  depth=_field(r"depth reached (\d+)", out),
                  seconds=time.monotonic() - t0,
                  violated=m.group(1) if m else "")


@pytest.fixture(scope="module")
def searches(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Search]]:
    """Every search of the module, two (or as many as there are cores) at a
    time, the longest first."""
    base = tmp_path_factory.mktemp("spin")
    jobs: list[tuple[str, list[str], str, list[str]]] = []
    for name, defines in CHECKS.items():
        # the two large searches (~10 M and ~3 M states) compiled for
        # speed, with COLLAPSE (0.5 GB instead of 1.4 GB for the largest,
        # ~15 % more time); the small ones compiled fast
        large = "-DMAXCOR=1" in defines
        jobs.append((name, defines, "-O2" if large else "-O1", ["-DCOLLAPSE"] if large else []))
    for mutant, (defines, _) in MUTANTS.items():
        # short searches: the compile is most of the time, -O0 compiles fastest
        jobs.append((f"MUTANT_{mutant}", [*defines, f"-DMUTANT_{mutant}"], "-O0", []))
    workers = max(1, min(2, os.cpu_count() or 1))
    t0 = time.monotonic()
    with ThreadPoolExecutor(max_workers=workers) as pool:
        futures: dict[str, Future[Search]] = {
            name: pool.submit(_search, name, defines, base / f"run{i}", opt, cc)
            for i, (name, defines, opt, cc) in enumerate(jobs)
        }
        results = {name: f.result() for name, f in futures.items()}
    print(f"\nspin searches: {len(results)} in {time.monotonic() - t0:.1f} s on {workers} workers")
    for r in results.values():
        print(f"  {r.name}: {r.states} states, depth {r.depth}, errors {r.errors}, {r.seconds:.1f} s"
              + (f", {r.violated}" if r.violated else ""))
    yield results


def test_every_mutant_of_the_model_is_checked() -> None:
    """A MUTANT_* added to the model without an entry here would go
    unchecked."""
    in_model = set(re.findall(r"\bMUTANT_([A-Z_]+)\b", MODEL.read_text()))
    assert in_model == set(MUTANTS)


@pytest.mark.parametrize("name", list(CHECKS))
def test_exhaustive_search_finds_no_violation(name: str, searches: dict[str, Search]) -> None:
    r = searches[name]
    assert r.returncode == 0, r.out
    assert "State-vector" in r.out and "Full statespace search" in r.out, r.out
    assert "assertion violations\t+" in r.out and "invalid end states\t+" in r.out, r.out
    assert r.errors == 0, f"{name}: {r.violated or 'invalid end state'}\n{r.out}"
    assert not r.truncated, r.out
    assert "Search not completed" not in r.out, r.out
    assert r.states >= MIN_STATES, r.out


@pytest.mark.parametrize("mutant", list(MUTANTS))
def test_mutant_is_caught(mutant: str, searches: dict[str, Search]) -> None:
    r = searches[f"MUTANT_{mutant}"]
    expected = MUTANTS[mutant][1]
    assert r.errors >= 1, f"MUTANT_{mutant} not caught:\n{r.out}"
    assert r.violated == f"assertion violated {expected}", (r.violated, r.out)
