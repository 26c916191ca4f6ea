"""Every test uses this tree's Python package (python/servoamp), not one
installed elsewhere in the environment: put it first on the path before any
test module imports ``servoamp``.

Boards (``scripts/test.sh --board NAME``, pytest's ``--board NAME``): a
test that runs on an emulated board belongs to that board, and only the
chosen boards' tests run (default: every folder of boards/ with a
board.yaml). Host tests always run. A test's board is, in this order:
its ``on_board(NAME)`` marker; a parameter whose value is a board's name
(or a board object with that ``name``); its folder (tests/zynqmp,
tests/robot/zynqmp: zynqmp_qemu); the ``zynqmp_images`` fixture; and
otherwise, for a test marked ``board`` or using the ``images``/``board``
fixtures, the first board, zynq7000_qemu.

Two QEMUs at once (``scripts/test.sh``'s default ``-j 2``: pytest-xdist
with ``--dist loadgroup``; ``-j 1`` is one process): every host
test is in one group, run in order on one worker as before (they share
build/ and make's outputs), with tests/viewer's board test (the viewer's
build and browser); a board test file is a group of its own (one boot
per module, as its fixtures want; a file parametrized by board is a group
per board), and each Robot suite is one. -icount keeps what a guest sees
independent of how many QEMUs share the host; the images are prepared
under a lock (servoamp.images)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import pytest

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "python"))
# tests/board_params.py (the boards a board suite is parametrized by), for
# the test modules of every folder
sys.path.insert(1, str(REPO / "tests"))

from board_params import board_names  # noqa: E402

FIRST_BOARD = "zynq7000_qemu"
# folders whose tests all belong to one board
BOARD_FOLDERS = {"tests/zynqmp": "zynqmp_qemu", "tests/robot/zynqmp": "zynqmp_qemu"}
# folders whose board tests share outputs or servers with their host tests
# (the viewer's build and Chromium): with -j N in the host group
SHARED_GROUPS = ("tests/viewer",)
# fixtures that boot (or build the images of) one board
BOARD_FIXTURES = {"zynqmp_images": "zynqmp_qemu", "images": FIRST_BOARD, "board": FIRST_BOARD}


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        "--board", action="append", default=[], metavar="NAME",
        help="run the tests of these emulated boards only (boards/NAME; repeat or separate with commas; "
             "default: every board); host tests always run",
    )


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "on_board(name): runs on the emulated board boards/<name> "
                                       "(selected with --board)")
    if config.pluginmanager.hasplugin("xdist") and config.getvalue("dist") == "loadgroup":
        config.pluginmanager.register(XdistGroupCheck(), "servoamp-xdist-group-check")


def chosen_boards(config: pytest.Config) -> list[str]:
    names = board_names()
    picked = [b for arg in config.getoption("board") for b in arg.split(",") if b]
    unknown = [b for b in picked if b not in names]
    if unknown:
        raise pytest.UsageError(f"--board {', '.join(unknown)}: no such board (have: {', '.join(names)})")
    return picked or names


def rel_dir(item: pytest.Item) -> str:
    """The test file's folder, relative to the repository."""
    return item.path.resolve().relative_to(REPO).parent.as_posix()


def item_board(item: pytest.Item, names: list[str]) -> str | None:
    """The board ``item`` runs on, or None for a host test."""
    mark = item.get_closest_marker("on_board")
    if mark is not None:
        return str(mark.args[0])
    callspec = getattr(item, "callspec", None)
    if callspec is not None:
        for value in callspec.params.values():
            name = value if isinstance(value, str) else getattr(value, "name", None)
            if isinstance(name, str) and name in names:
                return name
    rel = rel_dir(item)
    for folder, name in BOARD_FOLDERS.items():
        if rel == folder or rel.startswith(folder + "/"):
            return name
    fixtures = getattr(item, "fixturenames", ())
    for fixture, name in BOARD_FIXTURES.items():
        if fixture in fixtures:
            return name
    if item.get_closest_marker("board") is not None and not rel.startswith("tests/emulator"):
        return FIRST_BOARD      # tests/emulator: our QEMU's own tests, every machine
    return None


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    names = board_names()
    chosen = chosen_boards(config)
    keep: list[pytest.Item] = []
    drop: list[pytest.Item] = []
    parallel = config.pluginmanager.hasplugin("xdist")
    for item in items:
        board = item_board(item, names)
        if board is not None and board not in chosen:
            drop.append(item)
            continue
        keep.append(item)
        if parallel:
            if board is None or rel_dir(item).startswith(SHARED_GROUPS):
                group = "host"
            elif item.path.suffix == ".py" and "robot_suite" in item.name:
                group = item.nodeid           # one Robot suite, one boot
            else:
                # a test file on one board: its boots share module fixtures
                # (a file parametrized by board boots each board once: the
                # two boards' halves may run on two workers at once)
                group = f"{item.path.as_posix()}@{board}"
            item.add_marker(pytest.mark.xdist_group(group))
    if drop:
        config.hook.pytest_deselected(items=drop)
        items[:] = keep


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]) -> Any:
    """A failed test keeps the logs of every board still running (a module
    fixture's boot outlives the test: its run directory was removed at the
    module's end unless the fixture itself failed)."""
    rep = yield
    if rep.failed:
        from servoamp import runner
        if runner.mark_running_failed():
            print(f"[qemu] {item.nodeid} failed: the running boards' logs are kept", file=sys.stderr)
    return rep


class XdistGroupCheck:
    """With -j N, refuse to run if pytest-xdist lost the groups: its loadgroup
    scheduler reads a test's group from a suffix its workers append to the
    node id, and with pytest 9.2 that append has no effect (pytest-xdist
    issue 1386). The tests would spread over the workers as if ungrouped:
    host tests racing on build/, a board file booted once per worker.
    Every test collected under xdist has a group (above), so a worker's
    list without one suffix is that loss. (A class, registered by
    pytest_configure: xdist's hooks exist only where xdist is installed.)"""

    def pytest_xdist_node_collection_finished(self, node: object, ids: list[str]) -> None:
        if ids and not any("@" in i.rsplit("]", 1)[-1] for i in ids):
            pytest.exit(
                f"pytest {pytest.__version__} with pytest-xdist dropped every test's xdist_group "
                f"(e.g. {ids[0]}): -j N would run the groups apart (pytest-xdist issue 1386). "
                "pyproject.toml pins a pytest that keeps them: run scripts/bootstrap.sh, or use -j 1",
                returncode=pytest.ExitCode.USAGE_ERROR)
