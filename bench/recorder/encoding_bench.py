#!/usr/bin/env python3
"""Recording encodings before/after, in one run: ``servoamp record`` (JSON
messages, the mcap package) against ``servoamp bridge`` (protobuf through
foxglove-sdk, its WebSocket server up with no client), fed by the real
telemetry server (telem_feed: linux/telemetry's ring and server with a
synthetic plant) on 127.0.0.1.

    .venv/bin/python bench/recorder/encoding_bench.py [--axes 4,8] [--json bench/results/recorder.json]

For each axis count and encoding:

* bytes per cycle in the file, and host CPU per 1,000 cycles (all threads of
  the recorder process, imports excluded): 10,000 cycles at 2 kHz;
* the highest cycle rate one host core sustains with nothing dropped: the
  recorder pinned to one core (telem_feed to the other), the rate doubled
  from 1 kHz until a trial loses a cycle (telem_feed's ``client_lost`` /
  ``dropped``, or fewer cycles on file), then one bisection step; reported
  as rate x axes (axis-samples per second).

The host is shared (2 cores, other jobs running): the figures move between
runs; both encodings are measured in the same run, alternating.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "python"))
FEED = REPO / "build" / "telemetry" / "none" / "telem_feed"
ENCODINGS = ("json_record", "protobuf_sdk")


# ---- the recorder, in its own process ----------------------------------------------

def worker(enc: str, port: int, out: Path, cpu: int | None) -> dict[str, Any]:
    if cpu is not None:
        os.sched_setaffinity(0, {cpu})
    if enc == "json_record":
        from servoamp.record import record

        c0 = time.process_time()
        res = record("127.0.0.1", port, out, duration=120, reconnect=False)
        cpu_s = time.process_time() - c0
    else:
        from servoamp.bridge import Bridge

        c0 = time.process_time()
        b = Bridge("127.0.0.1", port, ws_port=0, mcap=out, reconnect=False)
        res = b.run(duration=120)
        b.close()
        cpu_s = time.process_time() - c0
    return {"cycles": res.cycles, "cpu_s": cpu_s, "wall_s": res.wall_s,
            "gaps": len(res.gaps), "bytes": out.stat().st_size}


def trial(enc: str, axes: int, rate: int, cycles: int, tmp: Path, pin: bool) -> dict[str, Any]:
    out = tmp / f"{enc}_{axes}_{rate}.mcap"
    feed_cmd = [str(FEED), "--addr", "127.0.0.1", "--port", "0", "--cycles", str(cycles),
                "--rate", str(rate), "--axes", str(axes), "--wait-clients", "1",
                "--ring", "8192", "--log-every", "1000", "--param-every", "5000"]
    if pin:
        feed_cmd = ["taskset", "-c", "0"] + feed_cmd
    feed = subprocess.Popen(feed_cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert feed.stdout is not None
        port = int(feed.stdout.readline().split()[2])
        w = subprocess.run([sys.executable, __file__, "--worker", enc, "--port", str(port),
                            "--out", str(out)] + (["--cpu", "1"] if pin else []),
                           capture_output=True, text=True, timeout=300,
                           env=dict(os.environ, PYTHONPATH=str(REPO / "python")))
        fout, _ferr = feed.communicate(timeout=120)
    finally:
        if feed.poll() is None:
            feed.kill()
            feed.communicate()
    if w.returncode != 0:
        raise RuntimeError(f"worker {enc}: {w.stderr[-2000:]}")
    r = json.loads(w.stdout.strip().splitlines()[-1])
    f = json.loads(fout.strip().splitlines()[-1])
    r["feed"] = {k: f[k] for k in ("sent", "dropped", "client_lost", "ring_high_water")}
    r["ok"] = (f["dropped"] == 0 and f["client_lost"] == 0 and r["cycles"] == f["sent"] == cycles)
    out.unlink(missing_ok=True)
    return r


def max_rate(enc: str, axes: int, tmp: Path, seconds: float, top: int) -> dict[str, Any]:
    ok_rate, fail_rate, tried = 0, 0, []
    rate = 1000
    while rate <= top:
        r = trial(enc, axes, rate, int(rate * seconds), tmp, pin=True)
        tried.append({"rate_hz": rate, "ok": r["ok"], "cycles": r["cycles"], **r["feed"]})
        if not r["ok"]:
            fail_rate = rate
            break
        ok_rate = rate
        rate *= 2
    if fail_rate and ok_rate:
        mid = (ok_rate + fail_rate) // 2
        r = trial(enc, axes, mid, int(mid * seconds), tmp, pin=True)
        tried.append({"rate_hz": mid, "ok": r["ok"], "cycles": r["cycles"], **r["feed"]})
        if r["ok"]:
            ok_rate = mid
    return {"max_rate_hz": ok_rate, "max_rate_x_axes": ok_rate * axes,
            "limited_by_ramp_top": fail_rate == 0, "trials": tried}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--axes", default="4,8")
    ap.add_argument("--json", type=Path, default=REPO / "bench" / "results" / "recorder.json")
    ap.add_argument("--cycles", type=int, default=10000, help="cycles of the size/CPU run")
    ap.add_argument("--seconds", type=float, default=2.0, help="length of one ramp trial")
    ap.add_argument("--top", type=int, default=128000, help="highest rate tried (Hz)")
    ap.add_argument("--worker", choices=ENCODINGS)
    ap.add_argument("--port", type=int)
    ap.add_argument("--out", type=Path)
    ap.add_argument("--cpu", type=int)
    ap.add_argument("--quick", action="store_true",
                    help="tiny sizes (scripts/bench.sh --quick): 1000 cycles, 0.3 s trials, ramp top 8 kHz")
    args = ap.parse_args()
    if args.quick:
        args.cycles, args.seconds, args.top = 1000, 0.3, 8000
    if args.worker:
        print(json.dumps(worker(args.worker, args.port, args.out, args.cpu)))
        return 0
    subprocess.run(["make", "-s", "-C", str(REPO / "linux" / "telemetry")], check=True)
    tmp = REPO / "build" / "bench" / "recorder"
    tmp.mkdir(parents=True, exist_ok=True)
    res: dict[str, Any] = {
        "command": "bench/recorder/encoding_bench.py " + " ".join(sys.argv[1:]),
        "host": {"cpus": os.cpu_count(), "machine": platform.machine(),
                 "load_avg_at_start": list(os.getloadavg())},
        "note": "shared 2-core host; recorder pinned to CPU 1, telem_feed to CPU 0 for the "
                "rate ramp; both encodings measured in this run, alternating",
        "benchmark": "recorder",
        "encodings": {e: {} for e in ENCODINGS},
        "figures": [],
    }
    axes_list = [int(a) for a in args.axes.split(",")]
    for axes in axes_list:
        for enc in ENCODINGS:
            r = trial(enc, axes, 2000, args.cycles, tmp, pin=False)
            d = {"cycles": r["cycles"], "file_bytes": r["bytes"],
                 "bytes_per_cycle": round(r["bytes"] / max(1, r["cycles"]), 1),
                 "cpu_ms_per_1000_cycles": round(r["cpu_s"] * 1e6 / max(1, r["cycles"]), 2),
                 "nothing_dropped": r["ok"]}
            res["encodings"][enc][str(axes)] = d
    for axes in axes_list:
        for enc in ENCODINGS:
            res["encodings"][enc][str(axes)].update(max_rate(enc, axes, tmp, args.seconds,
                                                             args.top))
    # the table's figures (bench/README.md): both encodings, then the
    # after/before ratios measured in this run
    kinds = (("bytes_per_cycle", "B", "lower"), ("cpu_ms_per_1000_cycles", "ms", "lower"),
             ("max_rate_x_axes", "1/s", "higher"))
    for enc in ENCODINGS:
        for axes in axes_list:
            d = res["encodings"][enc][str(axes)]
            for k, unit, better in kinds:
                res["figures"].append({"name": f"{enc}_{axes}_axes_{k}", "value": d[k], "unit": unit,
                                       "better": better})
    for axes in axes_list:
        j, p = res["encodings"]["json_record"][str(axes)], res["encodings"]["protobuf_sdk"][str(axes)]
        for k, _, better in kinds:
            if j[k]:
                res["figures"].append({
                    "name": f"ratio_{axes}_axes_{k}", "value": round(p[k] / j[k], 3), "unit": "x",
                    "better": better, "note": "protobuf_sdk / json_record, same run"})
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(res, indent=2) + "\n")
    print(f"{'figure':<44} {'json_record':>14} {'protobuf_sdk':>14}")
    for axes in axes_list:
        for k, unit in (("bytes_per_cycle", "B"), ("cpu_ms_per_1000_cycles", "ms CPU"),
                        ("max_rate_x_axes", "axis-samples/s")):
            j = res["encodings"]["json_record"][str(axes)][k]
            p = res["encodings"]["protobuf_sdk"][str(axes)][k]
            print(f"{axes} axes {k} ({unit})".ljust(44) + f" {j:>14} {p:>14}")
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
