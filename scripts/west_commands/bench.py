# SPDX-License-Identifier: MIT
"""``west bench``: run servoamp's benchmarks and print one table of every
figure against its target.

    west bench                         # all of them (board ones boot QEMU)
    west bench transport motion        # some of them
    west bench -b zynqmp_qemu cycle    # a board benchmark on one board (-b repeatable;
                                       # default: every board, host benchmarks once)
    west bench --list                  # names, host/board, on which board, duration, command
    west bench --table                 # only the table of bench/results
    west bench --quick transport       # tiny configuration, build/bench/quick

This is scripts/bench.sh (which installs what is needed through
scripts/bootstrap.sh, then runs python/servoamp/bench.py); bench/README.md
describes the benchmarks, the results schema and bench/targets.toml.

Also runs without a west workspace: ``scripts/bench.sh``.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
DESCRIPTION = "run the benchmarks and print each figure against its target"


def run(argv: list[str]) -> int:
    return subprocess.call([str(REPO / "scripts" / "bench.sh"), *argv], cwd=REPO)


try:
    from west.commands import WestCommand

    class Bench(WestCommand):
        def __init__(self) -> None:
            super().__init__("bench", DESCRIPTION, __doc__ or "", accepts_unknown_args=True)

        def do_add_parser(self, parser_adder):  # type: ignore[no-untyped-def]
            # No arguments of its own: everything after `west bench` (NAME...,
            # -b/--board NAME, --list, --table, --quick, --results DIR, -v,
            # -h for scripts/bench.sh's help) reaches scripts/bench.sh as
            # west's unknown arguments, in the order given. (A REMAINDER
            # positional does not take a leading option: `west bench -b X
            # cycle` came out as `X cycle -b`.)
            return parser_adder.add_parser(self.name, help=self.help, description=self.description,
                                           formatter_class=argparse.RawDescriptionHelpFormatter,
                                           add_help=False)

        def do_run(self, args, unknown):  # type: ignore[no-untyped-def]
            rc = run(list(unknown))
            if rc:
                sys.exit(rc)

except ImportError:  # plain Python, no west
    pass


if __name__ == "__main__":
    sys.exit(run(sys.argv[1:]))
