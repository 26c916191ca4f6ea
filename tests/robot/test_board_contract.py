"""Static checks of the zynq7000_qemu board (no QEMU boot): the numbers of
board.yaml, the Linux devicetree, the firmware engineer's servo.dts and the
boot stub agree; the DT bindings validate; the remoteproc driver is
checkpatch-clean and builds without warnings."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from servoamp import qemu

REPO = Path(__file__).resolve().parents[2]


def fdtget(dtb: Path, node: str, prop: str, typ: str = "x") -> list[int] | str:
    out = subprocess.run(["fdtget", "-t", typ, str(dtb), node, prop], capture_output=True, text=True, check=True).stdout.strip()
    return out if typ == "s" else [int(v, 16) for v in out.split()]


@pytest.fixture(scope="module")
def dtb(board: qemu.Board) -> Path:
    kdir = qemu.kernel_dir()
    return qemu.build_dtb(board, qemu.kernel_source(kdir))  # raises on dtc warnings


def test_linux_dt_matches_board_yaml(board: qemu.Board, dtb: Path) -> None:
    s = board.data["servo"]
    rp = "/axi/remoteproc@ffff8000"
    assert fdtget(dtb, "/reserved-memory/servo-carveout@1f000000", "reg") == [s["carveout"]["base"], s["carveout"]["size"]]
    assert fdtget(dtb, "/axi/ocm-mailbox@ffff0000", "reg") == [s["mailbox"]["base"], s["mailbox"]["size"]]
    assert fdtget(dtb, rp, "reg") == [s["control_word"], 8, s["boot_register"], 4]
    assert s["status_word"] == s["control_word"] + 4
    assert fdtget(dtb, rp, "servoamp,park-address") == [board.addr("load", "park_loop")]
    assert fdtget(dtb, "/memory@0", "reg") == [board.addr("ddr", "base"), board.addr("ddr", "size")]
    bootargs = fdtget(dtb, "/chosen", "bootargs", "s")
    assert isinstance(bootargs, str)
    assert "maxcpus=1" in bootargs and f"console={board.data['linux']['console']}" in bootargs
    assert fdtget(dtb, "/axi/serial@e0001000", "status", "s") == "disabled"
    assert fdtget(dtb, "/axi/timer@f8002000", "status", "s") == "disabled"


def test_servo_dts_agrees(board: qemu.Board) -> None:
    """The firmware side (boards/<board>/servo.dts) uses the same carveout."""
    servo = board.folder / "servo.dts"
    if not servo.exists():
        pytest.skip("servo.dts not written yet")
    text = servo.read_text()
    c = board.data["servo"]["carveout"]
    assert re.search(rf"reg\s*=\s*<\s*{c['base']:#010x}\s+{c['size']:#010x}\s*>", text), "carveout differs in servo.dts"


@pytest.mark.parametrize("park_wfe", [True, False], ids=["wfe", "icount"])
def test_boot_stub_park_loop_address(board: qemu.Board, park_wfe: bool) -> None:
    """Both stubs (CPU1 parked in wfe for the host clock, polling for
    -icount) keep the park loop at the contract address."""
    binary = qemu.build_stub(board, park_wfe=park_wfe)
    nm = subprocess.run(["arm-none-eabi-nm", str(binary.with_suffix(".elf"))], capture_output=True, text=True,
                        check=True).stdout
    syms = {ln.split()[2]: int(ln.split()[0], 16) for ln in nm.splitlines() if len(ln.split()) == 3}
    assert syms["_start"] == board.addr("load", "boot_stub")
    assert syms["park"] == board.addr("load", "park_loop")
    assert binary.stat().st_size <= 4096
    dis = subprocess.run(["arm-none-eabi-objdump", "-d", str(binary.with_suffix(".elf"))], capture_output=True,
                         text=True, check=True).stdout
    assert ("\twfe" in dis) == park_wfe


def test_bindings_validate() -> None:
    tool = Path(sys.executable).with_name("dt-doc-validate")
    bindings = sorted((REPO / "devicetree" / "bindings").rglob("*.yaml"))
    res = subprocess.run([str(tool), *map(str, bindings)], capture_output=True, text=True)
    assert res.returncode == 0 and not res.stderr.strip(), res.stderr


def test_driver_checkpatch_clean() -> None:
    kdir = qemu.kernel_dir()
    script = qemu.kernel_source(kdir) / "scripts" / "checkpatch.pl"
    sources = [("remoteproc", "zynq_servo_rproc.c"), ("remoteproc", "zynq_servo_rproc_check.h"),
               ("uio", "servoamp_cycle_uio.c")]
    for folder, src in sources:
        res = subprocess.run([str(script), "--no-tree", "--strict", "-f", src],
                             cwd=REPO / "linux" / folder, capture_output=True, text=True)
        assert "total: 0 errors, 0 warnings, 0 checks" in res.stdout, res.stdout


@pytest.mark.parametrize("folder", sorted(qemu.KERNEL_MODULES))
def test_driver_builds_without_warnings(folder: str, tmp_path: Path) -> None:
    """Each module against the board's kernel (its build variant:
    SERVOAMP_KERNEL) with -Werror (the kernel's default for W=0)."""
    kdir = qemu.kernel_dir()
    res = subprocess.run(["make", "-C", str(REPO / "linux" / folder), f"KDIR={kdir / 'obj'}", f"BUILD={tmp_path}"],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stdout + res.stderr
    assert "warning" not in (res.stdout + res.stderr).lower(), res.stdout + res.stderr
    assert (tmp_path / qemu.KERNEL_MODULES[folder]).exists()


def test_network_entry_agrees(board: qemu.Board) -> None:
    """board.yaml's network entry, the Python launcher's defaults and the
    telemetry library's default port are the same numbers."""
    from servoamp import netboard

    net = board.data["network"]
    assert net["nic"] == netboard.NIC_MODEL
    assert net["guest_addr"] == netboard.GUEST_ADDR
    assert net["telemetry_port"] == netboard.TELEMETRY_PORT
    header = (REPO / "linux" / "telemetry" / "telem.h").read_text()
    m = re.search(r"#define TELEM_DEFAULT_PORT (\d+)u", header)
    assert m and int(m.group(1)) == net["telemetry_port"]


def test_rproc_words_defined_once() -> None:
    """The control and status words (STOP, RUN!, PRKD, CRSH) have one
    definition, include/servoamp/rproc_words.h, which the driver, rpu_app
    and the test firmware include; no source holds their numbers again
    (documentation may quote them)."""
    words = qemu.rproc_words()
    ascii_of = {"ZSR_CTRL_STOP": b"STOP", "ZSR_STATUS_RUNNING": b"RUN!", "ZSR_STATUS_PARKED": b"PRKD",
                "ZSR_STATUS_CRASHED": b"HSRC"}  # CRSH: "CRSH" in (little-endian) memory
    for name, text in ascii_of.items():
        assert words[name] == int.from_bytes(text, "big"), name
    header = "include/servoamp/rproc_words.h"
    for user in ("linux/remoteproc/zynq_servo_rproc.c", "rpu_app/src/board.h", "tests/robot/fixtures/test_fw.S"):
        assert '#include "servoamp/rproc_words.h"' in (REPO / user).read_text(), user
    numbers = re.compile("|".join(f"{words[n]:#010x}" for n in ascii_of), re.I)
    files = subprocess.run(["git", "ls-files"], cwd=REPO, capture_output=True, text=True, check=True).stdout.split()
    docs = ("docs/", "devicetree/bindings/")
    found = [f"{f}:{n}" for f in files
             if f != header and not f.startswith(docs) and not f.endswith(".md") and (REPO / f).is_file()
             for n, line in enumerate((REPO / f).read_text(errors="replace").splitlines(), 1)
             if numbers.search(line)]
    assert not found, f"the words again outside {header}: {found}"
