"""scripts/bench.sh / python/servoamp/bench.py: the benchmarks' entry point
and summary table. Real runs of the host benchmarks in their tiny
configurations (--quick), the schema of every results file, the targets
file. No figure is asserted: on a shared host they are noise-bound (the
figures themselves are in bench/results and the docs)."""

from __future__ import annotations

import fnmatch
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest

from servoamp import bench

TOP = Path(__file__).resolve().parents[2]


def _bench(*args: str | Path, timeout: int = 600) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "servoamp.bench", *map(str, args)], cwd=TOP,
                          capture_output=True, text=True, timeout=timeout,
                          env={**os.environ, "PYTHONPATH": str(TOP / "python")})


def test_bench_sh_lists_every_benchmark() -> None:
    p = subprocess.run([str(TOP / "scripts" / "bench.sh"), "--list"], cwd=TOP, capture_output=True,
                       text=True, timeout=600)
    assert p.returncode == 0, p.stdout + p.stderr
    listed = [line.split()[0] for line in p.stdout.splitlines() if line and not line[0].isspace()]
    assert listed == list(bench.BENCHMARKS)
    assert {"transport", "footprint", "motion", "cycle", "recorder"} <= set(listed)


def test_west_commands_yml_names_bench() -> None:
    text = (TOP / "scripts" / "west-commands.yml").read_text()
    assert "file: scripts/west_commands/bench.py" in text and "name: bench" in text and "class: Bench" in text
    p = subprocess.run([sys.executable, str(TOP / "scripts" / "west_commands" / "bench.py"), "--list"],
                       cwd=TOP, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0 and "transport" in p.stdout, p.stdout + p.stderr


def test_quick_host_benchmarks_write_valid_figures_and_one_table(tmp_path: Path) -> None:
    names = ["transport", "footprint", "motion"]
    p = _bench("--quick", "--results", tmp_path, *names)
    assert p.returncode == 0, p.stdout + p.stderr
    targets = bench.load_targets()
    cpu = bench._cpu_model()
    assert cpu != "?" or not Path("/proc/cpuinfo").read_text().count("model name")
    for n in names:
        doc = json.loads((tmp_path / f"{n}.json").read_text())
        assert bench.validate(doc) == [], n
        # the machine it was measured on, stamped by the runner
        assert doc["measured_on"]["cpu"] == cpu and doc["measured_on"]["cpus_online"] == os.cpu_count(), doc
        assert doc["measured_on"]["cache_cpu0"] == bench._caches(), doc["measured_on"]
        # every figure of these three is in the table, with its status
        for f in doc["figures"]:
            line = next((l for l in p.stdout.splitlines() if l.split()[:3] == [n, "host", f["name"]]), None)
            assert line is not None, (n, f["name"], p.stdout)
            if bench.find_target(targets, n, f["name"]):
                assert " pass " in line or " FAIL " in line, line
    assert p.stdout.count("bench  ") == 1  # one table header
    assert "targets met" in p.stdout and "[1] issue 1:" in p.stdout


def test_transport_blocks_alternate_and_report_spread(tmp_path: Path) -> None:
    p = _bench("--quick", "--results", tmp_path, "transport")
    assert p.returncode == 0, p.stdout + p.stderr
    doc = json.loads((tmp_path / "transport.json").read_text())
    blocks = doc["blocks"]
    assert blocks["pairs"] == 4 and blocks["round_trips_per_block"] == 500
    for key in ("a_p50_ns", "c_p50_ns", "a_p99_9_ns", "c_p99_9_ns"):
        assert len(blocks[key]) == 4 and all(v > 0 for v in blocks[key]), key
    for key in ("a_over_c_p50", "a_over_c_p99_9"):
        s = blocks[key]
        per = s["per_block"]
        q = key[len("a_over_c"):]  # _p50, _p99_9
        ratios = [a / c for a, c in zip(blocks[f"a{q}_ns"], blocks[f"c{q}_ns"])]
        assert per == pytest.approx(ratios, rel=2e-3, abs=1e-3)
        assert s["min"] == pytest.approx(min(per), abs=1e-3) and s["max"] == pytest.approx(max(per), abs=1e-3)
        assert s["min"] <= s["q1"] <= s["median"] <= s["q3"] <= s["max"]
    fig = {f["name"]: f for f in doc["figures"]}
    assert fig["a_over_c_p50"]["value"] == pytest.approx(blocks["a_over_c_p50"]["median"], abs=1e-3)
    assert fig["a_over_c_p50"]["spread"]["max"] == pytest.approx(blocks["a_over_c_p50"]["max"], abs=1e-3)


def _write(path: Path, doc: object) -> None:
    path.write_text(json.dumps(doc))


def test_table_shows_a_foreign_results_file_and_rejects_bad_ones(tmp_path: Path) -> None:
    # a file no runner here writes (another benchmark's), with its own target
    _write(tmp_path / "encoding.json", {"figures": [
        {"name": "bytes_per_cycle_json", "value": 900, "unit": "B", "better": "lower"},
        {"name": "bytes_per_cycle_protobuf", "value": 240, "unit": "B", "better": "lower",
         "target": 300, "target_source": "issue 15"},
        {"name": "cycles_per_s_8axes", "value": 2000, "unit": "1/s", "better": "higher", "target": 4000}]})
    p = _bench("--table", "--results", tmp_path)
    assert p.returncode == 0, p.stdout + p.stderr
    rows = {l.split()[2]: l for l in p.stdout.splitlines() if l.startswith("encoding ")}
    assert set(rows) == {"bytes_per_cycle_json", "bytes_per_cycle_protobuf", "cycles_per_s_8axes"}
    assert " pass " in rows["bytes_per_cycle_protobuf"] and "0.80" in rows["bytes_per_cycle_protobuf"]
    assert " FAIL " in rows["cycles_per_s_8axes"] and "0.50" in rows["cycles_per_s_8axes"]
    assert "1 of 2 targets met" in p.stdout

    bad = {
        "nofigures": {"iterations": 3},
        "badbetter": {"figures": [{"name": "x", "value": 1, "unit": "ns", "better": "faster"}]},
        "noname": {"figures": [{"value": 1, "unit": "ns", "better": "lower"}]},
        "dup": {"figures": [{"name": "x", "value": 1, "unit": "ns", "better": "lower"},
                            {"name": "x", "value": 2, "unit": "ns", "better": "lower"}]},
        "string": {"figures": [{"name": "x", "value": "1", "unit": "ns", "better": "lower"}]},
        "badname": {"figures": [{"name": "a.b", "value": 1, "unit": "ns", "better": "lower"}]},
    }
    for stem, doc in bad.items():
        assert bench.validate(doc), stem
        _write(tmp_path / f"{stem}.json", doc)
    assert bench.validate({"figures": [{"name": "x", "value": math.inf, "unit": "ns", "better": "lower"}]})
    p = _bench("--table", "--results", tmp_path)
    assert p.returncode == 1, p.stdout + p.stderr
    errs = {l.split()[0] for l in p.stdout.splitlines() if " error " in f" {l} "}
    assert errs == set(bad), p.stdout


def test_targets_toml_entries_and_patterns(tmp_path: Path) -> None:
    targets = bench.load_targets()
    for stem, figs in targets.items():
        for name, t in figs.items():
            assert t.source.strip(), (stem, name)
    # exact names win over patterns; the first matching pattern otherwise
    toml = tmp_path / "t.toml"
    toml.write_text('[r."size_*"]\ntarget = 1\nsource = "a"\n[r."size_big"]\ntarget = 2\nsource = "b"\n'
                    '[r."size_?ig"]\ntarget = 3\nsource = "c"\n')
    t = bench.load_targets(toml)
    assert bench.find_target(t, "r", "size_big").value == 2  # type: ignore[union-attr]
    assert bench.find_target(t, "r", "size_dig").value == 1  # type: ignore[union-attr]
    assert bench.find_target(t, "r", "other") is None and bench.find_target(t, "q", "size_big") is None
    toml.write_text('[r."x"]\ntarget = 1\n')  # no source
    with pytest.raises(ValueError):
        bench.load_targets(toml)
    toml.write_text('[r."x"]\ntarget = 1\nsource = "s"\nbetter = "faster"\n')
    with pytest.raises(ValueError):
        bench.load_targets(toml)


def test_committed_results_carry_figures_and_every_target_names_one() -> None:
    """Every file in bench/results matches the schema, and every target in
    bench/targets.toml whose results file exists matches a figure in it (a
    target that matches nothing is a typo or a renamed figure)."""
    results = TOP / "bench" / "results"
    docs = {p.stem: json.loads(p.read_text()) for p in results.glob("*.json")}
    assert {"transport", "footprint", "motion", "cycle", "cycle-zynqmp_qemu"} <= set(docs)
    for stem, doc in docs.items():
        assert bench.validate(doc) == [], stem
    targets = bench.load_targets()
    # a benchmark's table applies to its file on every board
    for stem, doc in docs.items():
        name, _ = bench.split_stem(stem, bench.known_boards())
        names = [f["name"] for f in doc["figures"]]
        for table in {stem, name}:
            for pattern in targets.get(table, {}):
                assert any(fnmatch.fnmatchcase(n, pattern) for n in names), (stem, table, pattern)


def test_bench_module_is_mypy_strict() -> None:
    mypy = Path(sys.executable).parent / "mypy"
    p = subprocess.run([str(mypy), "--strict", str(TOP / "python" / "servoamp" / "bench.py")],
                       capture_output=True, text=True, timeout=300, cwd=TOP)
    assert p.returncode == 0, p.stdout + p.stderr


# ---- boards (issue 35, item 5: `west bench -b ...`) ----------------------

def test_boards_are_the_board_folders_first_board_first() -> None:
    boards = bench.known_boards()
    assert boards[0] == bench.FIRST_BOARD == "zynq7000_qemu" and "zynqmp_qemu" in boards
    assert all((TOP / "boards" / b / "board.yaml").exists() for b in boards)
    assert bench.results_stem("cycle", "zynq7000_qemu") == "cycle"
    assert bench.results_stem("cycle", "zynqmp_qemu") == "cycle-zynqmp_qemu"
    assert bench.results_stem("transport", None) == "transport"
    assert bench.split_stem("cycle-zynqmp_qemu", boards) == ("cycle", "zynqmp_qemu")
    assert bench.split_stem("cycle", boards) == ("cycle", "zynq7000_qemu")
    assert bench.split_stem("transport", boards) == ("transport", "host")
    # every board benchmark names its boards (and they exist); host ones none
    for b in bench.BENCHMARKS.values():
        assert bool(b.boards) == b.board, b.name
        assert set(b.boards) <= set(boards), b.name
        if b.board and set(boards) - set(b.boards):
            assert b.not_yet.strip(), f"{b.name}: no reason for the boards it skips"


def _list(*args: str) -> dict[str, list[str]]:
    p = _bench("--list", *args)
    assert p.returncode == 0, p.stdout + p.stderr
    out: dict[str, list[str]] = {}
    for line in p.stdout.splitlines():
        if line and not line[0].isspace():
            cur = out.setdefault(line.split()[0], [])
        elif line.strip().startswith("on "):
            cur.append(line.strip())
    return out


def test_list_shows_which_benchmark_runs_on_which_board() -> None:
    every = _list()
    assert list(every) == list(bench.BENCHMARKS)
    assert every["cycle"] == ["on zynq7000_qemu: runs (cycle.json)",
                              "on zynqmp_qemu: runs (cycle-zynqmp_qemu.json)"]
    for name in ("transport", "footprint", "motion"):
        assert every[name] == [], name      # host: no board lines
    assert every["rt_latency"] == ["on zynq7000_qemu: runs (rt_latency.json)",
                                   "on zynqmp_qemu: runs (rt_latency-zynqmp_qemu.json)"]
    for name in ("determinism", "fieldbus"):
        zq = [l for l in every[name] if l.startswith("on zynqmp_qemu: ")]
        assert len(zq) == 1 and zq[0].startswith("on zynqmp_qemu: skipped: not yet: "), every[name]
        assert every[name][0] == f"on zynq7000_qemu: runs ({name}.json)"
    one = _list("-b", "zynqmp_qemu")
    assert one["cycle"] == ["on zynqmp_qemu: runs (cycle-zynqmp_qemu.json)"]
    assert all(l.startswith("on zynqmp_qemu: ") for ls in one.values() for l in ls)


def test_an_unknown_board_is_refused_with_the_known_ones() -> None:
    for args in (("--list", "-b", "zynq9000_qemu"), ("-b", "zynqmp_qemu", "--board", "nope", "cycle"),
                 ("--table", "-b", "zynq9000_qemu")):
        p = _bench(*args)
        assert p.returncode == 2, p.stdout + p.stderr
        assert "unknown board" in p.stderr and "(boards: zynq7000_qemu, zynqmp_qemu;" in p.stderr, p.stderr
        assert p.stdout == "", p.stdout     # nothing ran, no table


def test_a_benchmark_not_ported_to_a_board_is_skipped_with_its_reason(tmp_path: Path) -> None:
    p = _bench("-b", "zynqmp_qemu", "--results", tmp_path, "determinism", "fieldbus")
    assert p.returncode == 0, p.stdout + p.stderr
    for name in ("determinism", "fieldbus"):
        why = bench.BENCHMARKS[name].why_not("zynqmp_qemu")
        assert why and f"[bench] {name} on zynqmp_qemu: skipped: {why}" in p.stdout, p.stdout
    assert "running" not in p.stdout and list(tmp_path.iterdir()) == []
    # the plan: host benchmarks once, board benchmarks once per chosen board
    steps = [(b.name, board, why is None) for b, board, why in bench.plan([], bench.known_boards())]
    assert steps.count(("transport", None, True)) == 1
    assert ("cycle", "zynq7000_qemu", True) in steps and ("cycle", "zynqmp_qemu", True) in steps
    assert ("determinism", "zynqmp_qemu", False) in steps and ("rt_latency", "zynqmp_qemu", True) in steps
    assert [s for s in bench.plan(["cycle"], ["zynqmp_qemu"])] == [(bench.BENCHMARKS["cycle"], "zynqmp_qemu", None)]


def _figs(**values: float) -> dict[str, object]:
    return {"figures": [{"name": k, "value": v, "unit": "cycles", "better": "lower"} for k, v in values.items()]}


def test_table_prints_each_boards_figures_against_the_targets(tmp_path: Path) -> None:
    _write(tmp_path / "cycle.json", {**_figs(virtual_1000us_missed_servo=0, max_rate_khz_8axes=8),
                                     "board": "zynq7000_qemu"})
    _write(tmp_path / "cycle-zynqmp_qemu.json", {**_figs(virtual_1000us_missed_servo=3, max_rate_khz_8axes=2),
                                                 "board": "zynqmp_qemu"})
    _write(tmp_path / "footprint.json", _figs(code_cortex_r5=1))
    p = _bench("--table", "--results", tmp_path)
    assert p.returncode == 0, p.stdout + p.stderr
    rows = {tuple(l.split()[:3]): l for l in p.stdout.splitlines() if l.startswith(("cycle ", "footprint "))}
    assert set(rows) == {("cycle", b, f) for b in ("zynq7000_qemu", "zynqmp_qemu")
                         for f in ("virtual_1000us_missed_servo", "max_rate_khz_8axes")} | \
        {("footprint", "host", "code_cortex_r5")}
    # the same targets ([cycle] in bench/targets.toml) on both boards
    assert " pass " in rows[("cycle", "zynq7000_qemu", "virtual_1000us_missed_servo")]
    assert " FAIL " in rows[("cycle", "zynqmp_qemu", "virtual_1000us_missed_servo")]
    assert " pass " in rows[("cycle", "zynq7000_qemu", "max_rate_khz_8axes")]
    assert " FAIL " in rows[("cycle", "zynqmp_qemu", "max_rate_khz_8axes")]
    assert ">= 4 " in rows[("cycle", "zynqmp_qemu", "max_rate_khz_8axes")]
    assert "2 of 4 targets met" in p.stdout
    # -b: that board's figures, and the host ones
    p = _bench("--table", "--results", tmp_path, "-b", "zynqmp_qemu")
    assert p.returncode == 0, p.stdout + p.stderr
    boards = {l.split()[1] for l in p.stdout.splitlines() if l.startswith(("cycle ", "footprint "))}
    assert boards == {"zynqmp_qemu", "host"}, p.stdout
    # NAME selects a benchmark on every board
    p = _bench("--table", "--results", tmp_path, "cycle")
    assert {l.split()[1] for l in p.stdout.splitlines() if l.startswith("cycle ")} == \
        {"zynq7000_qemu", "zynqmp_qemu"} and "footprint " not in p.stdout


def test_a_boards_own_targets_come_before_the_benchmarks(tmp_path: Path) -> None:
    toml = tmp_path / "t.toml"
    toml.write_text('[cycle."*_missed_*"]\ntarget = 0\nsource = "design"\n'
                    '["cycle-zynqmp_qemu"."max_rate_*"]\ntarget = 2\nsource = "r5"\n'
                    '[cycle."max_rate_*"]\ntarget = 4\nsource = "a9"\n')
    t = bench.load_targets(toml)
    assert bench.find_target(t, "cycle-zynqmp_qemu", "max_rate_khz_8axes", "cycle").source == "r5"  # type: ignore[union-attr]
    assert bench.find_target(t, "cycle", "max_rate_khz_8axes", "cycle").source == "a9"  # type: ignore[union-attr]
    assert bench.find_target(t, "cycle-zynqmp_qemu", "x_missed_y", "cycle").source == "design"  # type: ignore[union-attr]
    assert bench.find_target(t, "cycle-zynqmp_qemu", "x_missed_y") is None  # no benchmark: its own table only


def test_west_bench_passes_every_argument_in_order() -> None:
    """`west bench -b zynqmp_qemu cycle` reaches scripts/bench.sh as typed
    (west parses its command line with parse_known_args: the command's
    parser must leave every argument to the unknown ones, in order)."""
    pytest.importorskip("west")
    import argparse
    import importlib.util
    spec = importlib.util.spec_from_file_location("west_bench", TOP / "scripts" / "west_commands" / "bench.py")
    assert spec and spec.loader
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    calls: list[list[str]] = []
    mod.run = lambda argv: calls.append(argv) or 0
    cmd = mod.Bench()
    top = argparse.ArgumentParser(add_help=False)
    cmd.do_add_parser(top.add_subparsers(dest="command"))
    for argv in (["-b", "zynqmp_qemu", "cycle"], ["--list", "-b", "zynqmp_qemu", "--board", "zynq7000_qemu"],
                 ["--results", "x", "transport"], ["-h"], []):
        args, unknown = top.parse_known_args(["bench", *argv])
        cmd.do_run(args, unknown)
        assert calls.pop() == argv
