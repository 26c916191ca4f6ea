"""Fault injection on the running board (python -m servoamp.faults): one
boot, every fault of the catalogue injected while the cycle runs and the
recorder records. Each must be detected by the side that should see it,
handled as it should be (remoteproc recovery, or a safe stop held until
`ampctl resume`, or repaired in place), with servod and the kernel still up,
and every cycle servod handled present in the recording.

Before the fixes of issue 13 this failed on: the servo line's epoch word
garbled (link "peer absent" for good), both semaphore words garbled (the
mailbox blocked until the next epoch), the servo's cycle interrupt disabled
(the firmware never saw STOP from its wfi, the recovery failed)."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from servoamp import faults, netboard, qemu

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.board
def test_every_fault_detected_and_recovered(images: qemu.Images) -> None:
    with netboard.ControllerBoard(images=images) as cb:
        cb.start_servod(faults.SERVOD_ARGS)
        cb.start_firmware()
        r = faults.run_campaign(board=cb)
    out = REPO / "build" / "faults.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(r, indent=1) + "\n")
    print(faults.markdown(r))
    bad = [f"{o['name']}: {o['detected_by'] or '-'}; {o['recovery'] or '-'}; crashes {o['crashes']}; "
           f"{'; '.join(o['notes'])}" for o in r["faults"] if not o["ok"]]
    assert not bad, "faults not handled:\n" + "\n".join(bad)
    assert {o["name"] for o in r["faults"]} == {f.name for f in faults.FAULTS}
    assert r["data_lost"] == 0, r["recording"]
    assert r["recording"]["recorded_cycles"] > 1000
