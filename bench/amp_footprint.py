#!/usr/bin/env python3
"""Footprint of the servo-side amp_lib on the servo cores.

Builds amp_common.c + amp_servo.c with arm-none-eabi-gcc -Os for the
bare-metal port, links them with --gc-sections keeping only the servo API
(what a firmware links), and prints .text/.data/.bss per target; writes
bench/results/footprint.json. Targets: Cortex-A9 (ARM and Thumb-2) and
Cortex-R5 (Thumb-2). Budget: 2,048 B of code, 64 B of data+bss.

Then the real firmware: rpu_app built for each board that has a servo
devicetree (the Zynq-7000's A9, the ZynqMP's R5), its image (code and
data+bss) and amp_lib's share of the code, from the link map.
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
from pathlib import Path

TOP = Path(__file__).resolve().parent.parent
SOURCES = ["amp_common.c", "amp_servo.c"]
SERVO_API = [
    "amp_servo_attach", "amp_servo_heartbeat", "amp_servo_set_state",
    "amp_servo_cycle_rx", "amp_servo_cycle_tx", "amp_servo_mbox_poll",
    "amp_servo_mbox_respond",
]
TARGETS = {
    "cortex-a9-thumb2": ["-mcpu=cortex-a9", "-mthumb"],
    "cortex-a9-arm": ["-mcpu=cortex-a9", "-marm"],
    "cortex-r5-thumb2": ["-mcpu=cortex-r5", "-mthumb"],
}
BUDGET_CODE = 2048
BUDGET_DATA = 64


def build(target: str, flags: list[str], work: Path, cc: str) -> dict[str, int]:
    objs = []
    for src in SOURCES:
        obj = work / f"{target}-{src}.o"
        subprocess.run(
            [cc, *flags, "-mfloat-abi=soft", "-std=c11", "-Os", "-Wall", "-Wextra", "-Werror",
             "-ffreestanding", "-ffunction-sections", "-fdata-sections",
             "-DAMP_BOARD_TICKS_PER_US=100",
             f"-I{TOP}/amp_lib/include", f"-I{TOP}/amp_lib/src",
             f"-I{TOP}/amp_lib/port/baremetal-armv7",
             "-c", str(TOP / "amp_lib" / "src" / src), "-o", str(obj)],
            check=True)
        objs.append(str(obj))
    elf = work / f"{target}.elf"
    keep = [f"-Wl,-u,{s}" for s in SERVO_API]
    # memcpy/memset are the firmware's; left unresolved on purpose
    subprocess.run(
        [cc, *flags, "-nostdlib", "-Wl,--gc-sections", f"-Wl,-e,{SERVO_API[0]}", *keep,
         "-Wl,--unresolved-symbols=ignore-all", "-o", str(elf), *objs],
        check=True)
    out = subprocess.run([cc.replace("gcc", "size"), "-A", str(elf)],
                         check=True, capture_output=True, text=True).stdout
    sizes = {"text": 0, "rodata": 0, "data": 0, "bss": 0}
    for line in out.splitlines():
        parts = line.split()
        if len(parts) >= 2 and parts[0].startswith("."):
            name, size = parts[0], int(parts[1])
            for key in sizes:
                if name == f".{key}" or name.startswith(f".{key}."):
                    sizes[key] += size
    sizes["code"] = sizes["text"] + sizes["rodata"]
    return sizes


FIRMWARE_BOARDS = sorted(p.parent.name for p in (TOP / "boards").glob("*/servo.dts"))


def firmware(board: str, work: Path) -> dict[str, int]:
    """rpu_app for the board (rpu_app/Makefile, its defaults): the image's
    code (text + rodata), data + bss, and the code linked from amp_lib's
    objects (the link map's input sections from obj/amp_lib/)."""
    build = work / f"rpu_app-{board}"
    subprocess.run(["make", "-s", "-C", str(TOP / "rpu_app"), "-j2", f"BOARD={board}", f"BUILD={build}",
                    f"PYTHON={sys.executable}"], check=True, capture_output=True)
    out = subprocess.run(["arm-none-eabi-size", "-A", str(build / "servo.elf")],
                         check=True, capture_output=True, text=True).stdout
    sec = {p[0]: int(p[1]) for p in (ln.split() for ln in out.splitlines()) if len(p) >= 2 and p[0].startswith(".")}
    code = sum(v for k, v in sec.items() if k in (".vectors", ".text", ".rodata", ".resource_table"))
    ram = sum(v for k, v in sec.items() if k in (".data", ".bss"))
    amp = 0
    mapped = (build / "servo.map").read_text()
    for m in re.finditer(r"^ \.(?:text|rodata)\S*\s+0x[0-9a-f]+\s+(0x[0-9a-f]+)\s+(\S+)$", mapped, re.M):
        if "/amp_lib/" in m.group(2):
            amp += int(m.group(1), 16)
    return {"code": code, "data_bss": ram, "amp_lib_code": amp}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cc", default="arm-none-eabi-gcc")
    ap.add_argument("--json", default=str(TOP / "bench" / "results" / "footprint.json"))
    args = ap.parse_args()
    results: dict[str, dict[str, int]] = {}
    images: dict[str, dict[str, int]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for target, flags in TARGETS.items():
            results[target] = build(target, flags, Path(tmp), args.cc)
        for board in FIRMWARE_BOARDS:
            images[board] = firmware(board, Path(tmp))
    print(f"servo-side amp_lib footprint (arm-none-eabi-gcc -Os, --gc-sections), "
          f"budget {BUDGET_CODE} B code, {BUDGET_DATA} B data+bss")
    print(f"{'target':<18} {'.text':>6} {'.rodata':>8} {'code':>6} {'.data':>6} {'.bss':>6}")
    for target, s in results.items():
        print(f"{target:<18} {s['text']:>6} {s['rodata']:>8} {s['code']:>6} {s['data']:>6} {s['bss']:>6}")
    print("reference: RPMsg-Lite static API 2,926 B flash, 352 B RAM")
    print("\nthe servo firmware (rpu_app, -O2), per board: its image and amp_lib's share of the code")
    print(f"{'board':<18} {'code':>7} {'data+bss':>9} {'amp_lib':>8} {'share':>6}")
    for board, f in images.items():
        print(f"{board:<18} {f['code']:>7} {f['data_bss']:>9} {f['amp_lib_code']:>8} "
              f"{100 * f['amp_lib_code'] / f['code']:>5.1f}%")
    # the summary table's figures (bench/README.md); the budgets are in
    # bench/targets.toml
    figures = []
    for target, s in results.items():
        note = ".text + .rodata"
        if "-marm" in TARGETS[target]:
            note += "; ARM state, for comparison: the firmware builds amp_lib as Thumb-2"
        figures.append({"name": f"code_{target}", "value": s["code"], "unit": "B", "better": "lower",
                        "note": note})
        figures.append({"name": f"data_bss_{target}", "value": s["data"] + s["bss"], "unit": "B",
                        "better": "lower"})
    for board, f in images.items():
        figures.append({"name": f"firmware_code_{board}", "value": f["code"], "unit": "B", "better": "lower",
                        "note": "rpu_app's image: vectors, text, rodata, resource table"})
        figures.append({"name": f"firmware_amp_lib_share_{board}",
                        "value": round(100 * f["amp_lib_code"] / f["code"], 1), "unit": "%", "better": "lower",
                        "note": "amp_lib's code in the image, from the link map"})
    Path(args.json).parent.mkdir(parents=True, exist_ok=True)
    Path(args.json).write_text(json.dumps(
        {"benchmark": "footprint", "compiler": args.cc, "flags": "-Os -ffunction-sections -Wl,--gc-sections",
         "budget": {"code": BUDGET_CODE, "data_bss": BUDGET_DATA},
         "targets": results, "firmware": images, "figures": figures}, indent=2) + "\n")
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
