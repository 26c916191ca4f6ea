# SPDX-License-Identifier: MIT
"""``west build``: build a servoamp firmware application for a board.

    west build -b zynq7000_qemu rpu_app            # build/rpu_app/zynq7000_qemu
    west build -b zynq7000_qemu -d /tmp/b rpu_app  # another build directory
    west build -p always -b zynq7000_qemu rpu_app  # start from an empty build dir
    west build -b zynq7000_qemu rpu_app -- AMP_LIB=0 MMU=0   # extra make arguments
    west build -b zynqmp_qemu --variant can rpu_app  # boards/zynqmp_qemu/servo-can.dts: the axes on
                                                     # CAN drives, build/rpu_app/zynqmp_qemu-can

Only the application's Makefile builds (rpu_app/Makefile): this command
resolves the board (boards/<board>/servo.dts must exist) and the variant
(``--variant V``: boards/<board>/servo-V.dts, the build directory
build/<app>/<board>-V, the same folders as the images' builds in
python/servoamp/images.py), the source and build directories, applies the pristine policy and runs make. Outputs of
rpu_app: servo.elf (with resource table), servo-norsc.elf (without), the
generated board_config.h / board_memory.ld, link maps, and qemu-stub.elf
(for QEMU runs without Linux).

Pristine (-p/--pristine): ``never`` keeps the build directory; ``always``
empties it first; ``auto`` (default) empties it only when it was last used
for another board or application. A build directory is only ever emptied
if it is empty or carries this command's marker file, so ``-d`` pointing
at an unrelated directory is refused rather than wiped.

Also runs without a west workspace:
``.venv/bin/python scripts/west_commands/build.py -b zynq7000_qemu rpu_app``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
MARKER = ".servoamp-build.json"
DESCRIPTION = "build a servoamp firmware application (rpu_app) for a board"


class BuildError(Exception):
    pass


def add_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    parser.add_argument("-b", "--board", help="board folder under boards/ (required unless the build dir remembers one)")
    parser.add_argument("-d", "--build-dir", type=Path, help="build directory (default: build/<app>/<board> in the repository)")
    parser.add_argument("-p", "--pristine", nargs="?", const="always", default="auto",
                        choices=["auto", "always", "never"],
                        help="empty the build directory first: auto (default, on board/app change), always, never; "
                             "-p alone means always")
    parser.add_argument("--variant", help="a devicetree variant of the board: boards/<board>/servo-VARIANT.dts "
                                          "(e.g. can: the axes on CiA 402 drives over CAN)")
    parser.add_argument("-j", "--jobs", type=int, default=2, help="make -j value (default: %(default)s)")
    parser.add_argument("-v", "--verbose", action="store_true", help="show full compiler command lines")
    parser.add_argument("source_dir", nargs="?", default="rpu_app",
                        help="application directory (default: %(default)s), relative to the current "
                             "directory or to the repository")
    parser.add_argument("make_args", nargs=argparse.REMAINDER,
                        help="after --: extra make arguments, e.g. -- AMP_LIB=0 MMU=0")
    return parser


def boards() -> list[str]:
    return sorted(p.parent.name for p in (REPO / "boards").glob("*/servo.dts"))


def resolve_source(src: str) -> Path:
    for cand in (Path.cwd() / src, REPO / src):
        if (cand / "Makefile").is_file():
            return cand.resolve()
    raise BuildError(f"no application with a Makefile at '{src}' (looked in {Path.cwd()} and {REPO})")


def read_marker(build_dir: Path) -> dict[str, Any] | None:
    """The marker 'west build' leaves in a build directory (a JSON object),
    or None when there is none or it is not one."""
    try:
        marker = json.loads((build_dir / MARKER).read_text())
    except (FileNotFoundError, ValueError):
        return None
    return marker if isinstance(marker, dict) else None


def make_pristine(build_dir: Path) -> None:
    if not build_dir.exists():
        return
    if any(build_dir.iterdir()) and read_marker(build_dir) is None:
        raise BuildError(f"refusing to empty {build_dir}: not a build directory made by 'west build' "
                         f"(no {MARKER}); choose another -d or remove it yourself")
    shutil.rmtree(build_dir)


def run(args: argparse.Namespace) -> int:
    app = resolve_source(args.source_dir)
    board = args.board
    if args.build_dir is not None:
        build_dir = args.build_dir if args.build_dir.is_absolute() else Path.cwd() / args.build_dir
        marker = read_marker(build_dir)
        if board is None and marker:
            board = marker.get("board")
    if not board:
        raise BuildError("no board: use -b BOARD (available: " + ", ".join(boards()) + ")")
    if board not in boards():
        raise BuildError(f"unknown board '{board}' (available: {', '.join(boards())})")
    dts = None
    if args.variant:
        dts = REPO / "boards" / board / f"servo-{args.variant}.dts"
        if not dts.is_file():
            have = sorted(p.stem[len("servo-"):] for p in (REPO / "boards" / board).glob("servo-*.dts"))
            raise BuildError(f"board '{board}' has no variant '{args.variant}' (available: {', '.join(have) or 'none'})")
    if args.build_dir is None:
        build_dir = REPO / "build" / app.name / (board + (f"-{args.variant}" if args.variant else ""))
    build_dir = build_dir.resolve()

    marker = read_marker(build_dir)
    want = {"board": board, "source": str(app)} | ({"variant": args.variant} if args.variant else {})
    if args.pristine == "always":
        make_pristine(build_dir)
    elif args.pristine == "auto" and marker is not None and marker != want:
        print(f"-- west build: {build_dir} was built for {marker}, now {want}: making it pristine")
        make_pristine(build_dir)
    elif args.pristine == "auto" and marker is None and build_dir.exists() and any(build_dir.iterdir()):
        # A directory the Makefile made directly (no marker): it is ours if
        # it holds our generated header; otherwise do not touch it.
        if not (build_dir / "board_config.h").exists():
            raise BuildError(f"{build_dir} is not empty and is not a build directory; use another -d")

    build_dir.mkdir(parents=True, exist_ok=True)
    (build_dir / MARKER).write_text(json.dumps(want) + "\n")

    extra = [a for a in args.make_args if a != "--"]
    cmd = ["make", "-C", str(app), f"-j{args.jobs}", f"BOARD={board}", f"BUILD={build_dir}",
           f"PYTHON={sys.executable}"] + ([f"DTS={dts}"] if dts else []) + (["V=1"] if args.verbose else []) + extra
    print(f"-- west build: board {board}{f', variant {args.variant}' if args.variant else ''}, source {app}, "
          f"build dir {build_dir}")
    print("-- west build: " + " ".join(cmd))
    rc = subprocess.call(cmd, env=dict(os.environ))
    if rc == 0:
        outs = [p for p in ("servo.elf", "servo-norsc.elf") if (build_dir / p).exists()]
        print(f"-- west build: done: {', '.join(str(build_dir / p) for p in outs)}")
    return rc


try:
    from west.commands import WestCommand

    class Build(WestCommand):
        def __init__(self) -> None:
            super().__init__("build", DESCRIPTION, __doc__ or "", accepts_unknown_args=False)

        def do_add_parser(self, parser_adder):  # type: ignore[no-untyped-def]
            parser = parser_adder.add_parser(self.name, help=self.help, description=self.description,
                                             formatter_class=argparse.RawDescriptionHelpFormatter)
            return add_arguments(parser)

        def do_run(self, args, unknown):  # type: ignore[no-untyped-def]
            try:
                rc = run(args)
            except BuildError as e:
                self.die(str(e))
            if rc:
                sys.exit(rc)

except ImportError:  # plain Python, no west
    pass


if __name__ == "__main__":
    p = add_arguments(argparse.ArgumentParser(prog="build", description=__doc__,
                                              formatter_class=argparse.RawDescriptionHelpFormatter))
    try:
        sys.exit(run(p.parse_args()))
    except BuildError as e:
        print(f"build: error: {e}", file=sys.stderr)
        sys.exit(1)
