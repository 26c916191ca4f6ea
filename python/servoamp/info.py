"""Summary of a servoamp MCAP recording (``servoamp info``)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from servoamp import mcapio


def _pct(sorted_vals: list[float], q: float) -> float:
    if not sorted_vals:
        return 0.0
    k = min(len(sorted_vals) - 1, max(0, int(round(q * (len(sorted_vals) - 1)))))
    return sorted_vals[k]


def summarize(path: Path | str) -> dict[str, Any]:
    """Duration, cycles, exchange statuses, missed, latencies, parameter
    changes, gaps, log lines; works on finalized and on truncated files."""
    res = mcapio.ReadResult(False, "")
    topics = [mcapio.T_CYCLE, mcapio.T_GAP, mcapio.T_PARAM, mcapio.T_STATS,
              mcapio.T_SESSION, mcapio.T_LOG]
    cycles = 0
    t_first: int | None = None
    t_last: int | None = None
    c_first: int | None = None
    c_last: int | None = None
    exchange: dict[str, int] = {}
    missed = 0
    wake: list[float] = []
    irq: list[float] = []
    params: list[dict[str, Any]] = []
    gaps: list[dict[str, Any]] = []
    sessions: list[dict[str, Any]] = []
    last_stats: dict[str, Any] | None = None
    logs = 0
    logs_by_level: dict[int, int] = {}
    for topic, t, m in mcapio.iter_json(path, topics, res):
        if topic == mcapio.T_CYCLE:
            cycles += 1
            if t_first is None or t < t_first:
                t_first = t
            if t_last is None or t > t_last:
                t_last = t
            if c_first is None:
                c_first = m["cycle"]
            c_last = m["cycle"]
            exchange[m["exchange"]] = exchange.get(m["exchange"], 0) + 1
            missed += m["missed"]
            wake.append(m["wake_latency_ns"])
            irq.append(m["irq_latency_ns"])
        elif topic == mcapio.T_PARAM:
            params.append(dict(m, t_ns=t))
        elif topic == mcapio.T_GAP:
            gaps.append(dict(m, t_ns=t))
        elif topic == mcapio.T_STATS:
            last_stats = m
        elif topic == mcapio.T_SESSION:
            sessions.append(m)
        elif topic == mcapio.T_LOG:
            logs += 1
            logs_by_level[m["level"]] = logs_by_level.get(m["level"], 0) + 1
    wake.sort()
    irq.sort()
    # the recorder's own account, written when it finished (absent after a SIGKILL)
    rec_meta = next((m.metadata for m in mcapio.read_metadata(path)
                     if m.name == "servoamp.recording"), None)
    bad_frames = int(rec_meta.get("bad_frames", "0")) if rec_meta is not None else None
    lost_known = sum(g["lost"] or 0 for g in gaps)
    first = sessions[0] if sessions else {}
    return {
        "file": str(path),
        "complete": res.complete,
        "read_error": res.error,
        "controller_id": first.get("controller_id", ""),
        "n_axes": first.get("n_axes", 0),
        "cycle_period_ns": first.get("cycle_period_ns", 0),
        "connections": len(sessions),
        "duration_s": ((t_last - t_first) / 1e9) if t_first is not None and t_last is not None
        else 0.0,
        "cycles": cycles,
        "first_cycle": c_first,
        "last_cycle": c_last,
        "exchange": dict(sorted(exchange.items())),
        "missed": missed,
        "wake_latency_ns": {"max": wake[-1] if wake else 0, "p99": _pct(wake, 0.99),
                            "p50": _pct(wake, 0.5)},
        "irq_latency_ns": {"max": irq[-1] if irq else 0, "p99": _pct(irq, 0.99),
                           "p50": _pct(irq, 0.5)},
        "max_latency_ns": max(wake[-1] if wake else 0, irq[-1] if irq else 0),
        "parameter_changes": params,
        "gaps": gaps,
        "lost_cycles": lost_known,
        "gaps_with_unknown_loss": sum(1 for g in gaps if g["lost"] is None),
        "log_lines": logs,
        "log_lines_by_level": {str(k): v for k, v in sorted(logs_by_level.items())},
        "last_stats": last_stats,
        "bad_frames": bad_frames,
        "bad_frames_by_type": json.loads(rec_meta.get("bad_frames_by_type", "{}"))
        if rec_meta is not None else None,
    }


def format_text(s: dict[str, Any]) -> str:
    lines = [
        f"file:        {s['file']}" + ("" if s["complete"] else
                                      f"  (NOT finalized; read up to: {s['read_error']})"),
        f"controller:  {s['controller_id']}  axes {s['n_axes']}  period "
        f"{s['cycle_period_ns'] / 1e3:.0f} us  connections {s['connections']}",
        f"duration:    {s['duration_s']:.3f} s",
        f"cycles:      {s['cycles']}  ({s['first_cycle']} .. {s['last_cycle']})",
        "exchange:    " + ", ".join(f"{k} {v}" for k, v in s["exchange"].items()),
        f"missed:      {s['missed']} servo records skipped",
        f"latency:     wake-up max {s['wake_latency_ns']['max'] / 1e3:.1f} us "
        f"(p99 {s['wake_latency_ns']['p99'] / 1e3:.1f}), servo irq max "
        f"{s['irq_latency_ns']['max'] / 1e3:.2f} us (p99 {s['irq_latency_ns']['p99'] / 1e3:.2f})",
        f"parameters:  {len(s['parameter_changes'])} changes",
    ]
    for p in s["parameter_changes"][:20]:
        lines.append(f"  cycle {p['cycle']}: {p['name']} = {p['value']:g} {p['unit']}")
    lines.append(f"gaps:        {len(s['gaps'])}  ({s['lost_cycles']} cycles lost"
                 + (f", {s['gaps_with_unknown_loss']} of unknown size" if
                    s["gaps_with_unknown_loss"] else "") + ")")
    for g in s["gaps"][:20]:
        lines.append(f"  {g['reason']} ({g['source']}): cycles {g['from_cycle']} .. "
                     f"{g['to_cycle']}, lost {g['lost']}")
    lines.append(f"log lines:   {s['log_lines']}")
    if s["bad_frames"]:
        lines.append(f"bad frames:  {s['bad_frames']} skipped by the recorder ("
                     + ", ".join(f"{k} {v}" for k, v in s["bad_frames_by_type"].items()) + ")")
    return "\n".join(lines)


def main_info(path: str, as_json: bool) -> int:
    s = summarize(path)
    print(json.dumps(s, indent=2) if as_json else format_text(s))
    return 0
