"""PNG figures from a servoamp MCAP recording (``servoamp plot``)."""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from servoamp import mcapio  # noqa: E402


def _load(path: Path | str) -> dict[str, Any]:
    d: dict[str, Any] = {"t": [], "cx": [], "cy": [], "ax": [], "ay": [], "wake": [], "irq": [],
                         "ferr": {}, "ferr_t": {}, "pos_cmd": {}, "pos_act": {},
                         "q_t": [], "q": {}, "gaps": [], "params": []}
    for topic, t, m in mcapio.iter_json(path):
        if topic == mcapio.T_PATH:
            d["cx"].append(m["command"]["x"])
            d["cy"].append(m["command"]["y"])
            d["ax"].append(m["actual"]["x"])
            d["ay"].append(m["actual"]["y"])
        elif topic.startswith("/servoamp/axis/"):
            i = m["axis"]
            d["ferr_t"].setdefault(i, []).append(t)
            d["ferr"].setdefault(i, []).append(m["feedback"]["following_error"])
            d["pos_cmd"].setdefault(i, []).append(m["command"]["target_pos"])
            d["pos_act"].setdefault(i, []).append(m["feedback"]["actual_pos"])
        elif topic == mcapio.T_CYCLE:
            d["t"].append(t)
            d["wake"].append(m["wake_latency_ns"] / 1e3)
            d["irq"].append(m["irq_latency_ns"] / 1e3)
        elif topic == mcapio.T_QUEUES:
            d["q_t"].append(t)
            for k, v in m["levels"].items():
                d["q"].setdefault(k, []).append(v)
        elif topic == mcapio.T_GAP:
            d["gaps"].append((t, m))
        elif topic == mcapio.T_PARAM:
            d["params"].append((t, m))
    return d


def _t0(d: dict[str, Any]) -> int:
    cands = [d["t"][0]] if d["t"] else []
    cands += [v[0] for v in d["ferr_t"].values() if v]
    return min(cands) if cands else 0


def _marks(ax: Any, d: dict[str, Any], t0: int) -> None:
    for t, g in d["gaps"]:
        ax.axvline((t - t0) / 1e9, color="red", lw=0.8, ls="--", alpha=0.7)
    for t, _p in d["params"]:
        ax.axvline((t - t0) / 1e9, color="gray", lw=0.6, ls=":", alpha=0.6)


def read_queue_csv(path: Path | str) -> tuple[list[float], dict[str, list[float]]]:
    """motion_cli --trace CSV: t_us,<queue>,<queue>,..."""
    t: list[float] = []
    cols: dict[str, list[float]] = {}
    with open(path, newline="") as f:
        rd = csv.reader(f)
        head = next(rd)
        names = head[1:]
        for n in names:
            cols[n] = []
        for row in rd:
            if len(row) != len(head):
                continue
            t.append(float(row[0]) / 1e6)
            for n, v in zip(names, row[1:]):
                cols[n].append(float(v))
    return t, cols


def plot(path: Path | str, outdir: Path | str, queues_csv: Path | str | None = None,
         dpi: int = 110) -> list[Path]:
    """Writes xy_path.png, following_error.png, position.png, latency_histogram.png
    and queue_levels.png (when queue levels are available). Returns the files."""
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    d = _load(path)
    t0 = _t0(d)
    name = Path(path).name
    files: list[Path] = []

    if d["cx"]:
        fig, ax = plt.subplots(figsize=(6.4, 6.4))
        ax.plot(d["cx"], d["cy"], lw=1.2, label="commanded")
        ax.plot(d["ax"], d["ay"], lw=0.8, ls="--", label="actual")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("axis 0 position (increments)")
        ax.set_ylabel("axis 1 position (increments)")
        ax.set_title(f"XY path: commanded vs actual\n{name}")
        ax.legend(loc="upper right")
        ax.grid(True, alpha=0.3)
        files.append(out / "xy_path.png")
        fig.savefig(files[-1], dpi=dpi, bbox_inches="tight")
        plt.close(fig)

    if d["ferr"]:
        axes = sorted(d["ferr"])
        fig, axs = plt.subplots(len(axes), 1, figsize=(9, 1.6 * len(axes) + 1), sharex=True,
                                squeeze=False)
        for k, i in enumerate(axes):
            a = axs[k][0]
            a.plot([(t - t0) / 1e9 for t in d["ferr_t"][i]], d["ferr"][i], lw=0.7)
            a.set_ylabel(f"axis {i}")
            a.grid(True, alpha=0.3)
            _marks(a, d, t0)
        axs[-1][0].set_xlabel("time (s, controller clock)")
        fig.suptitle(f"following error per axis (increments)\n{name}")
        files.append(out / "following_error.png")
        fig.savefig(files[-1], dpi=dpi, bbox_inches="tight")
        plt.close(fig)

        fig, axs = plt.subplots(len(axes), 1, figsize=(9, 1.6 * len(axes) + 1), sharex=True,
                                squeeze=False)
        for k, i in enumerate(axes):
            a = axs[k][0]
            tt = [(t - t0) / 1e9 for t in d["ferr_t"][i]]
            a.plot(tt, d["pos_cmd"][i], lw=1.0, label="command")
            a.plot(tt, d["pos_act"][i], lw=0.7, ls="--", label="actual")
            a.set_ylabel(f"axis {i}")
            a.grid(True, alpha=0.3)
        axs[0][0].legend(loc="upper right", fontsize="small")
        axs[-1][0].set_xlabel("time (s, controller clock)")
        fig.suptitle(f"position: command vs actual (increments)\n{name}")
        files.append(out / "position.png")
        fig.savefig(files[-1], dpi=dpi, bbox_inches="tight")
        plt.close(fig)

    if d["wake"]:
        fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4))
        a1.hist(d["wake"], bins=80, color="tab:blue")
        a1.set_yscale("log")
        a1.set_xlabel("servod wake-up latency (us)")
        a1.set_ylabel("cycles")
        a1.set_title(f"max {max(d['wake']):.1f} us, n={len(d['wake'])}")
        a2.hist(d["irq"], bins=80, color="tab:orange")
        a2.set_yscale("log")
        a2.set_xlabel("servo interrupt latency (us)")
        a2.set_title(f"max {max(d['irq']):.2f} us")
        fig.suptitle(f"cycle latency\n{name}")
        files.append(out / "latency_histogram.png")
        fig.savefig(files[-1], dpi=dpi, bbox_inches="tight")
        plt.close(fig)

    q_t: list[float] = []
    q: dict[str, list[float]] = {}
    source = ""
    if queues_csv is not None:
        q_t, q = read_queue_csv(queues_csv)
        source = f"motion_cli trace {Path(queues_csv).name}"
    elif d["q_t"]:
        q_t = [(t - t0) / 1e9 for t in d["q_t"]]
        q = {k: [float(x) for x in v] for k, v in d["q"].items()}
        source = "recorded /servoamp/queues"
    if q_t:
        fig, ax = plt.subplots(figsize=(9, 4))
        for qname, vals in q.items():
            ax.step(q_t[:len(vals)], vals, where="post", lw=0.9, label=qname)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("items in queue")
        ax.set_title(f"motion pipeline queue levels ({source})")
        ax.legend(loc="upper right", fontsize="small")
        ax.grid(True, alpha=0.3)
        files.append(out / "queue_levels.png")
        fig.savefig(files[-1], dpi=dpi, bbox_inches="tight")
        plt.close(fig)
    (out / "plots.json").write_text(json.dumps([str(f.name) for f in files]) + "\n")
    return files
