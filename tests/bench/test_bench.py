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
            line = next((l for l in p.stdout.splitlines() if l.split()[:2] == [n, f["name"]]), None)
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
    rows = {l.split()[1]: l for l in p.stdout.splitlines() if l.startswith("encoding ")}
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
    assert {"transport", "footprint", "motion", "cycle"} <= set(docs)
    for stem, doc in docs.items():
        assert bench.validate(doc) == [], stem
    targets = bench.load_targets()
    for stem, figs in targets.items():
        if stem not in docs:
            continue
        names = [f["name"] for f in docs[stem]["figures"]]
        for pattern in figs:
            assert any(fnmatch.fnmatchcase(n, pattern) for n in names), (stem, pattern)


def test_bench_module_is_mypy_strict() -> None:
    mypy = Path(sys.executable).parent / "mypy"
    p = subprocess.run([str(mypy), "--strict", str(TOP / "python" / "servoamp" / "bench.py")],
                       capture_output=True, text=True, timeout=300, cwd=TOP)
    assert p.returncode == 0, p.stdout + p.stderr
