#!/usr/bin/env python3
"""Writes tools/foxglove/servoamp-layout.json, the Foxglove layout for the
channels `servoamp bridge` serves live and records (docs/recording.md,
python/servoamp/schemas/servoamp.proto): command vs feedback per axis, the
XY path (commanded and actual), following errors, latencies, exchange
status and queue levels, the firmware log, statistics, gaps and the
controller's parameters (live connection).

    python3 tools/foxglove/make_layout.py [--axes N] [-o FILE]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
# the motion pipeline's queues plotted (motion/src/pipeline.c, queue_names)
QUEUES = ("blocks", "segments", "setpoints")


def _path(value: str, label: str) -> dict[str, Any]:
    return {"value": value, "enabled": True, "timestampMethod": "receiveTime", "label": label}


def _plot(title: str, paths: list[dict[str, Any]], **extra: Any) -> dict[str, Any]:
    cfg: dict[str, Any] = {"title": title, "paths": paths, "showXAxisLabels": True,
                           "showYAxisLabels": True, "showLegend": True,
                           "legendDisplay": "floating", "showPlotValuesInLegend": False,
                           "isSynced": True, "xAxisVal": "timestamp", "sidebarDimension": 240}
    cfg.update(extra)
    return cfg


def _split(first: Any, second: Any, direction: str, pct: float = 50) -> dict[str, Any]:
    return {"first": first, "second": second, "direction": direction, "splitPercentage": pct}


def _stack(ids: list[str], direction: str = "column") -> Any:
    if len(ids) == 1:
        return ids[0]
    mid = len(ids) // 2
    return _split(_stack(ids[:mid], direction), _stack(ids[mid:], direction), direction,
                  100.0 * mid / len(ids))


def layout(n_axes: int) -> dict[str, Any]:
    cfg: dict[str, Any] = {}
    axis_ids = []
    ax = "/servoamp/cycle.axes"
    for i in range(n_axes):
        pid = f"Plot!axis{i}"
        cfg[pid] = _plot(f"axis {i}: position command vs feedback", [
            _path(f"{ax}[{i}].command.target_pos", "command"),
            _path(f"{ax}[{i}].feedback.actual_pos", "actual"),
        ])
        axis_ids.append(pid)
    cfg["Plot!ferr"] = _plot("following error", [
        _path(f"{ax}[{i}].feedback.following_error", f"axis {i}") for i in range(n_axes)])
    cfg["Plot!xycmd"] = _plot("XY path, commanded (axis 0 / axis 1)",
                              [_path(f"{ax}[1].command.target_pos", "commanded")],
                              xAxisVal="custom",
                              xAxisPath={"value": f"{ax}[0].command.target_pos", "enabled": True})
    cfg["Plot!xyact"] = _plot("XY path, actual (axis 0 / axis 1)",
                              [_path(f"{ax}[1].feedback.actual_pos", "actual")],
                              xAxisVal="custom",
                              xAxisPath={"value": f"{ax}[0].feedback.actual_pos", "enabled": True})
    # the bridge's rate (Stats.cycle_rate_hz, controller time): a derivative
    # of the cycle counter over receive time would be as good as the
    # viewer's clock, which is the browser's on a live connection in Studio
    cfg["Plot!rate"] = _plot("cycle rate (cycles/s of controller time)", [
        _path("/servoamp/stats.cycle_rate_hz", "cycles/s")])
    cfg["Plot!latency"] = _plot("latency (ns)", [
        _path("/servoamp/cycle.wake_latency_ns", "servod wake-up"),
        _path("/servoamp/cycle.irq_latency_ns", "servo irq"),
    ])
    cfg["Plot!exchange"] = _plot("exchange status (0 fresh, 1 stale, 2 torn, 3 missed, "
                                 "4 invalid, 5 none) and queue levels", [
        _path("/servoamp/cycle.exchange", "exchange"),
        # protobuf maps reach the viewer as lists of {key, value}
        *[_path(f'/servoamp/queues.levels[:]{{key=="{q}"}}.value', q) for q in QUEUES],
    ])
    cfg["RosOut!log"] = {"searchTerms": [], "minLogLevel": 1, "topicToRender": "/servoamp/log"}
    # servod's counters (a map: {key, value} rows) as a table
    cfg["Table!stats"] = {"topicPath": "/servoamp/stats.counters"}
    cfg["RawMessages!gap"] = {"topicPath": "/servoamp/gap", "diffEnabled": False,
                              "diffMethod": "custom", "diffTopicPath": "",
                              "showFullMessageForDiff": False, "expansion": "all"}
    cfg["Parameters!params"] = {"title": "servod parameters (live connection)"}
    left = _stack(axis_ids)
    middle = _split(_split("Plot!xycmd", "Plot!xyact", "row"),
                    _split("Plot!ferr", _split(_split("Plot!rate", "Plot!latency", "row"),
                                               "Plot!exchange", "column"),
                           "column", 40), "column", 40)
    right = _split(_split("RosOut!log", "Parameters!params", "column", 50),
                   _split("Table!stats", "RawMessages!gap", "column", 60), "column", 60)
    return {
        "configById": cfg,
        "globalVariables": {},
        "userNodes": {},
        "playbackConfig": {"speed": 1},
        "layout": _split(left, _split(middle, right, "row", 65), "row", 30),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--axes", type=int, default=4)
    ap.add_argument("-o", "--output", default=str(HERE / "servoamp-layout.json"))
    a = ap.parse_args()
    Path(a.output).write_text(json.dumps(layout(a.axes), indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
