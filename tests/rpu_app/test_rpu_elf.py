# SPDX-License-Identifier: MIT
"""Static checks of the two firmware images with pyelftools: placement in
the carveout, the remoteproc resource table (servo.elf) and its absence
(servo-norsc.elf), and the invariants the restart relies on."""
from __future__ import annotations

import struct

import pytest
from elftools.elf.constants import P_FLAGS
from elftools.elf.elffile import ELFFile

from rpu_common import CONTRACT, _make

RSC_CARVEOUT, RSC_DEVMEM, RSC_TRACE, RSC_VDEV = 0, 1, 2, 3
VARIANTS = ["servo.elf", "servo-norsc.elf"]


def open_elf(path):
    f = open(path, "rb")
    return f, ELFFile(f)


def carveout(board_cfg):
    return board_cfg["BOARD_CARVEOUT_BASE"], board_cfg["BOARD_CARVEOUT_BASE"] + board_cfg["BOARD_CARVEOUT_SIZE"]


def test_board_config_matches_contract(board_cfg):
    for k, v in CONTRACT.items():
        assert board_cfg[k] == v, f"{k}: devicetree gives {board_cfg[k]:#x}, contract says {v:#x}"


@pytest.mark.parametrize("name", VARIANTS)
def test_elf_header(rpu_build, board_cfg, name):
    f, elf = open_elf(rpu_build / name)
    with f:
        h = elf.header
        assert elf.elfclass == 32 and elf.little_endian
        assert h.e_machine == "EM_ARM" and h.e_type == "ET_EXEC"
        lo, hi = carveout(board_cfg)
        assert lo <= h.e_entry < hi
        assert h.e_entry % 4 == 0, "entry must be ARM (not Thumb) code"
        text = elf.get_section_by_name(".text")
        assert text["sh_addr"] == lo, "image (vector table) must start the carveout"
        assert text["sh_addr"] % 32 == 0, "VBAR needs a 32-byte aligned vector table"


@pytest.mark.parametrize("name", VARIANTS)
def test_all_pt_load_inside_carveout(rpu_build, board_cfg, name):
    lo, hi = carveout(board_cfg)
    f, elf = open_elf(rpu_build / name)
    with f:
        loads = [s for s in elf.iter_segments() if s["p_type"] == "PT_LOAD"]
        assert loads
        for s in loads:
            for addr in (s["p_paddr"], s["p_vaddr"]):
                assert lo <= addr and addr + s["p_memsz"] <= hi, (
                    f"PT_LOAD {addr:#x}+{s['p_memsz']:#x} outside carveout {lo:#x}..{hi:#x}")
            assert s["p_filesz"] <= s["p_memsz"]
        # code executable, nothing executable outside the cacheable image part
        unc = board_cfg["BOARD_UNCACHED_BASE"]
        for s in loads:
            if s["p_vaddr"] >= unc:
                assert not s["p_flags"] & P_FLAGS.PF_X


@pytest.mark.parametrize("name", VARIANTS)
def test_restartable_without_reload(rpu_build, name):
    """No initialised writable data: a restart from the park loop without a
    reload (or with one) starts from the same state. .bss is cleared by
    start.S."""
    f, elf = open_elf(rpu_build / name)
    with f:
        data = elf.get_section_by_name(".data")
        assert data is None or data["sh_size"] == 0
        syms = {s.name for s in elf.get_section_by_name(".symtab").iter_symbols()}
        for needed in ("_start", "_vectors", "irq_entry", "irq_dispatch", "irq_register",
                       "cpu_park", "__bss_start", "__bss_end", "fault_report"):
            assert needed in syms, needed
        for libc in ("malloc", "free", "printf", "sbrk", "_sbrk"):
            assert libc not in syms, f"{libc} linked: no libc/dynamic allocation allowed"


def _symbol(elf, name):
    for s in elf.get_section_by_name(".symtab").iter_symbols():
        if s.name == name:
            return s
    raise KeyError(name)


def test_resource_table_well_formed(rpu_build, board_cfg):
    lo, hi = carveout(board_cfg)
    f, elf = open_elf(rpu_build / "servo.elf")
    with f:
        sec = elf.get_section_by_name(".resource_table")
        assert sec is not None, "servo.elf must have a .resource_table section"
        assert sec["sh_type"] == "SHT_PROGBITS" and sec["sh_flags"] & 0x2, "table must be loaded (ALLOC)"
        data = sec.data()
        addr, size = sec["sh_addr"], sec["sh_size"]
        assert lo <= addr and addr + size <= hi
        # the table is inside a PT_LOAD's file part (copied by the loader)
        assert any(s["p_type"] == "PT_LOAD" and s["p_vaddr"] <= addr and
                   addr + size <= s["p_vaddr"] + s["p_filesz"] for s in elf.iter_segments())

        ver, num, r0, r1 = struct.unpack_from("<4I", data, 0)
        assert ver == 1, "resource table version must be 1"
        assert (r0, r1) == (0, 0), "reserved words must be zero"
        assert num >= 1
        offsets = struct.unpack_from(f"<{num}I", data, 16)
        hdr_end = 16 + 4 * num
        traces = []
        for off in offsets:
            assert off % 4 == 0 and hdr_end <= off and off + 4 <= size, f"offset {off} out of range"
            (rtype,) = struct.unpack_from("<I", data, off)
            assert rtype in (RSC_CARVEOUT, RSC_DEVMEM, RSC_TRACE, RSC_VDEV) or rtype >= 128
            if rtype == RSC_TRACE:
                assert off + 4 + 12 + 32 <= size
                da, ln, res = struct.unpack_from("<3I", data, off + 4)
                name = data[off + 16:off + 48]
                traces.append((da, ln, res, name))
        assert len(traces) == 1, "exactly one RSC_TRACE entry"
        da, ln, res, name = traces[0]
        assert res == 0
        assert b"\0" in name and name.split(b"\0")[0] == b"servo_trace"
        assert lo <= da and da + ln <= hi, "trace buffer must lie inside the carveout"
        assert ln == board_cfg["BOARD_TRACE_SIZE"]
        tb = _symbol(elf, "trace_buf")
        assert tb["st_value"] == da and tb["st_size"] == ln
        assert da >= board_cfg["BOARD_UNCACHED_BASE"], "trace buffer must be in the non-cacheable part"
        # covered by a PT_LOAD (zero-filled, memsz) so remoteproc maps it
        assert any(s["p_type"] == "PT_LOAD" and s["p_vaddr"] <= da and
                   da + ln <= s["p_vaddr"] + s["p_memsz"] for s in elf.iter_segments())


def test_norsc_has_no_resource_table(rpu_build):
    f, elf = open_elf(rpu_build / "servo-norsc.elf")
    with f:
        assert elf.get_section_by_name(".resource_table") is None
        syms = {s.name for s in elf.get_section_by_name(".symtab").iter_symbols()}
        assert "servo_rsc_table" not in syms
        # still a complete firmware with the same trace buffer and entry
        assert "trace_buf" in syms and "_start" in syms


def test_variants_differ_only_by_table(rpu_build):
    sizes = {}
    for name in VARIANTS:
        f, elf = open_elf(rpu_build / name)
        with f:
            sizes[name] = {s.name: s["sh_size"] for s in elf.iter_sections()
                           if s["sh_flags"] & 0x2}
    a, b = sizes["servo.elf"], sizes["servo-norsc.elf"]
    assert set(a) - set(b) == {".resource_table"}
    assert abs(a[".text"] - b[".text"]) == 0


@pytest.mark.parametrize("opts", [("MMU=0",), ("NESTING=0",), ("AMP_LIB=0",), ("OPT=-Os",)])
def test_build_options(tmp_path, toolchain, board_cfg, opts):
    """Every documented make option builds warning-free (-Werror) and keeps
    the images inside the carveout."""
    b = tmp_path / "b"
    r = _make(b, *opts)
    assert r.returncode == 0, r.stdout + r.stderr
    lo, hi = carveout(board_cfg)
    for name in VARIANTS:
        f, elf = open_elf(b / name)
        with f:
            for s in elf.iter_segments():
                if s["p_type"] == "PT_LOAD":
                    assert lo <= s["p_paddr"] and s["p_paddr"] + s["p_memsz"] <= hi


@pytest.mark.parametrize("name", VARIANTS)
def test_svc_stack_guard_between_tables_and_stack(rpu_build, name):
    """Issue 13, item 5: a 4 KiB-aligned guard page (mapped no-access by
    mmu.c) lies directly below the SVC stack and above the translation
    tables, inside one 1 MiB section (one second-level table): the SVC stack
    cannot grow into the tables without a data abort."""
    f, elf = open_elf(rpu_build / name)
    with f:
        g0 = _symbol(elf, "__stack_guard_start")["st_value"]
        g1 = _symbol(elf, "__stack_guard_end")["st_value"]
        bottom = _symbol(elf, "__svc_stack_bottom")["st_value"]
        top = _symbol(elf, "__svc_stack_top")["st_value"]
        l1 = _symbol(elf, "l1_table")
        l2 = _symbol(elf, "l2_guard_table")
        assert g0 % 4096 == 0 and g1 - g0 >= 4096 and (g1 - g0) % 4096 == 0
        assert g1 == bottom and top - bottom == 16 * 1024
        assert g0 >> 20 == (g1 - 1) >> 20
        assert l1["st_value"] % 16384 == 0 and l2["st_value"] % 1024 == 0
        assert l1["st_value"] + l1["st_size"] <= g0 and l2["st_value"] + l2["st_size"] <= g0
        # nothing else lives in the guard page
        for s in elf.get_section_by_name(".symtab").iter_symbols():
            if s["st_size"] and s["st_info"]["type"] == "STT_OBJECT":
                assert not (s["st_value"] < g1 and s["st_value"] + s["st_size"] > g0), s.name
