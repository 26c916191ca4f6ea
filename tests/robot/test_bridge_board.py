"""``servoamp bridge`` on the emulated board, checked by an independent
client: the Foxglove WebSocket protocol's reference client
(@foxglove/ws-protocol, tools/mcap-verify/ws-check.mjs) connected to the
bridge, which is connected to servod's telemetry through the board's port
forward (with this boot's token).

The client subscribes and receives every cycle, in order, for 3 s of guest
time (its count equals servod's cycle counter over the same window: no
hole); lists servod's parameters with their values; sets pos_kp (the set
goes through servod's parameter path to the firmware and comes back on
/servoamp/param, and `ampctl param get` agrees); sets an out-of-range value
and gets servod's refusal as an error status, with nothing changed.

Before that, who may set (issue 21, python/servoamp/wsfront.py): a web page
of a foreign origin is refused before the upgrade and its setParameters
never reaches the firmware; a viewer of an allowed origin without the
bridge's token lists the parameters read-only, its set refused; `ampctl
param get` on the board shows pos_kp unchanged after both.

On both boards (the fixture is parametrized by board, one boot each)."""

from __future__ import annotations

import json
import os
import subprocess
import threading
from pathlib import Path
from typing import Any

import pytest

from board_params import BOARDS, board_images
from servoamp import bridge, info, netboard, wsprobe
from servoamp.record import RecordResult

pytestmark = pytest.mark.board

REPO = Path(__file__).resolve().parents[2]
WS_CHECK = REPO / "tools" / "mcap-verify" / "ws-check.mjs"


@pytest.fixture(scope="module", params=BOARDS)
def run(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    board, images = board_images(request.param)
    if not (REPO / "tools" / "mcap-verify" / "node_modules" / "@foxglove" / "ws-protocol").is_dir():
        pytest.fail("tools/mcap-verify/node_modules misses @foxglove/ws-protocol: "
                    "run scripts/bootstrap.sh")
    out: dict[str, Any] = {"path": tmp_path_factory.mktemp(f"bridge_board_{board.name}") / "run.mcap"}
    with netboard.ControllerBoard(board, images) as cb:
        cb.start_servod()
        cb.start_firmware()
        cb.wait_telemetry()
        # as tests/robot/04_cycle.robot: a 10-cycle watchdog trips on TCG hiccups
        cb.ampctl("param set wd_limit 50")
        cb.ampctl("resume", expected_rc=None)
        out["kp_before"] = cb.ampctl("param get pos_kp").strip().splitlines()[-1]
        b = bridge.Bridge("127.0.0.1", cb.host_port, token=cb.token, ws_port=0,
                          mcap=out["path"])
        stop = threading.Event()
        box: dict[str, RecordResult] = {}
        th = threading.Thread(target=lambda: box.setdefault("res", b.run(stop=stop)),
                              daemon=True)
        th.start()
        try:
            assert b.ws_url is not None and b.ws_port is not None and b.ws_url_plain
            while b.hello is None and th.is_alive():  # the bridge on servod's telemetry
                stop.wait(0.05)
            status, head, sk = wsprobe.upgrade(b.ws_port, "/", "https://evil.example")
            if status == 101:  # then the page's set would go through: sent, to be seen
                sk.sendall(wsprobe.text_frame(json.dumps({
                    "op": "setParameters", "id": "evil",
                    "parameters": [{"name": "pos_kp", "value": 99.0, "type": "float64"}]}).encode()))
                stop.wait(2)
            sk.close()
            out["evil"] = (status, head)
            ro = subprocess.run(
                ["node", str(WS_CHECK), b.ws_url_plain, "--seconds", "0.2", "--param", "pos_kp",
                 "--good", "71", "--readonly", "--origin", "http://localhost:5173",
                 "--timeout", "300"],
                capture_output=True, text=True, timeout=400,
                env=dict(os.environ, NODE_NO_WARNINGS="1"))
            out["ro"] = json.loads(ro.stdout) if ro.stdout.strip() else {}
            out["ro_rc"], out["ro_err"] = ro.returncode, ro.stderr
            out["kp_untouched"] = cb.ampctl("param get pos_kp").strip().splitlines()[-1]
            node = subprocess.run(
                ["node", str(WS_CHECK), b.ws_url, "--seconds", "3", "--param", "pos_kp",
                 "--good", "70", "--bad", "5000", "--timeout", "400"],
                capture_output=True, text=True, timeout=500,
                env=dict(os.environ, NODE_NO_WARNINGS="1"))
            out["ws"] = json.loads(node.stdout) if node.stdout.strip() else {}
            out["ws_rc"], out["ws_err"] = node.returncode, node.stderr
            out["kp_after"] = cb.ampctl("param get pos_kp").strip().splitlines()[-1]
            out["stats"] = cb.stats()
        finally:
            stop.set()
            th.join(timeout=30)
            b.close()
    out["res"] = box.get("res")
    return out


def test_every_cycle_in_order_through_the_reference_client(run: dict[str, Any]) -> None:
    ws = run["ws"]
    assert run["ws_rc"] == 0, (ws, run["ws_err"][-2000:])
    c = ws["cycles"]
    first, last = int(c["first"]), int(c["last"])
    print(f"reference client: {c['count']} cycles {first}..{last} over "
          f"{(int(c['last_t']) - int(c['first_t'])) / 1e9:.3f} s of guest time")
    assert int(c["last_t"]) - int(c["first_t"]) >= 3_000_000_000
    assert c["out_of_order"] == 0
    # servod's cycle counter over the same window: every one of them arrived
    assert c["count"] == last - first + 1
    assert c["count"] >= 2700  # 1 kHz: 3 s of guest time
    st = run["stats"]
    assert int(st["linux.cycles"]) > last
    assert int(st["telem.dropped"]) == 0 and int(st["telem.client_lost"]) == 0
    assert ws["axes"] == 4


def test_only_the_token_may_set(run: dict[str, Any]) -> None:
    status, head = run["evil"]
    assert status == 403 and "origin https://evil.example is not allowed" in head, head
    ro = run["ro"]
    assert run["ro_rc"] == 0, (ro, run["ro_err"][-2000:])
    assert "read-only" in ro["set_readonly"]["status"]
    assert ro["set_readonly"]["reply"] == ro["set_readonly"]["before"] == ro["list_after"]
    # on the board: the firmware's pos_kp as before both
    assert run["kp_untouched"] == run["kp_before"]


def test_parameters_from_the_app(run: dict[str, Any]) -> None:
    ws = run["ws"]
    assert run["ws_rc"] == 0, (ws, run["ws_err"][-2000:])
    names = {p["name"]: p["value"] for p in ws["param_list"]}
    # servod's whole table, with their current values
    assert {"axes", "cycle_period_us", "wd_limit", "pos_kp", "fine_steps"} <= set(names)
    assert names["wd_limit"] == 50 and names["axes"] == 4
    assert run["kp_before"] == f"pos_kp={names['pos_kp']:g} 1/s"
    # taken: back from servod on /servoamp/param and as a parameter update
    assert ws["set_good"] == {"reply": 70, "channel": 70, "update": 70}
    assert run["kp_after"] == "pos_kp=70 1/s"
    # refused by servod's range check: an error status, nothing changed
    assert "out of range [0, 2000]" in ws["set_bad"]["status"]
    assert ws["set_bad"]["reply"] == 70 and ws["list_after"] == 70
    assert [p["value"] for p in ws["param_changes"] if p["name"] == "pos_kp"] == [70]


def test_the_same_messages_in_mcap(run: dict[str, Any]) -> None:
    res = run["res"]
    assert res is not None and res.cycles > 0
    s = info.summarize(run["path"])
    assert s["complete"] and s["n_axes"] == 4 and s["cycles"] == res.cycles
    assert ("pos_kp", 70.0) in [(p["name"], p["value"]) for p in s["parameter_changes"]]
    assert s["lost_cycles"] == 0
