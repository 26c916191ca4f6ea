# SPDX-License-Identifier: MIT
"""The ZynqMP R5 platform's part of rpu_app's board generation
(rpu_app/scripts/gen_board_header.py loads it for an arm,cortex-r5f servo
CPU): the core's own PMU cycle counter as time base, the PMSAv7 MPU's
regions, the vectors in TCM (no VBAR), the RPU's own GIC, no cooperative
stop (Linux's upstream R5 driver powers the core down)."""

from __future__ import annotations

from typing import Any, Callable

CPU_COMPATIBLE = "arm,cortex-r5f"
NAME = "zynqmp_r5"
HAS_VBAR = False         # the vectors are at 0x0 (the ATCM): `vectors`
GIC_OWNED = True         # the RPU's GIC: this firmware enables it
GIC_IDS = 192            # the RPU GIC's IDs: 32 + 160 SPIs (PL-to-PS lines: 121-128, 136-143)
STOP_CONTRACT = False    # the upstream driver powers the core down
SLCR = False
MPU_REGIONS = 16         # the R5's PMSAv7 data regions
GUARD_REGIONS = 1        # mpu.c adds the SVC stack guard itself


def _pow2(n: int) -> bool:
    return n >= 32 and n & (n - 1) == 0


def check_carveout(carve: Any, servo: Any, base: int, size: int, unc: int, fail: Callable[..., Any]) -> None:
    if not _pow2(size) or base % size:
        fail(carve, "carveout must be a power of two in size, aligned to it (one MPU region)")
    if not _pow2(unc) or not unc < size:
        fail(servo, "uncached-size must be a power of two below the carveout size (one MPU region)")


def timers(edt: Any, cpu: Any, servo: Any, put: Callable[..., None], fail: Callable[..., Any],
           prop: Callable[..., Any], one_reg: Callable[..., Any], gic_id: Callable[..., Any]) -> list[Any]:
    """The time base: the core's own cycle counter (PMCCNTR) at its clock;
    no idle wake (nothing to poll for: no stop word). No device to map."""
    hz = prop(cpu, "clock-frequency")
    if hz % 1_000_000:
        fail(cpu, "clock-frequency must be a whole number of MHz")
    put("BOARD_CPU_HZ", hz, cpu.path)
    put("BOARD_TIMEBASE_TICKS_PER_US", hz // 1_000_000, "the core's PMU cycle counter")
    for name in ("global-timer", "idle-timer", "idle-wake-us"):
        if name in servo.props:
            fail(servo, f"'{name}': platform {NAME} has none (the time base is the core's cycle counter)")
    vec = prop(servo, "vectors")
    base, size = one_reg(vec)
    if base != 0:
        fail(vec, "the vectors must be at 0x0 (no VBAR; the driver starts the core at the low vectors)")
    put("BOARD_VECTORS_BASE", base, vec.path)
    put("BOARD_VECTORS_SIZE", size)
    return []


def _region(base: int, size: int) -> tuple[int, int]:
    """The smallest aligned power-of-two region covering [base, base+size)."""
    n = 32
    while True:
        b = base - base % n
        if b + n >= base + size:
            return b, n
        n *= 2


def memory_map(cfg: dict[str, Any], carve: Any, ocm: Any, devices: list[Any],
               fail: Callable[..., Any]) -> list[tuple[int, int, str, str]]:
    """MPU regions, lowest priority first (a later region wins where two
    overlap): the vectors (TCM), the carveout (image cacheable, top
    non-cacheable), OCM non-cacheable, every device the firmware uses.
    Nothing else is mapped: the background region stays off."""
    c_base, c_size = cfg["BOARD_CARVEOUT_BASE"], cfg["BOARD_CARVEOUT_SIZE"]
    unc = cfg["BOARD_UNCACHED_SIZE"]
    regions = [
        (cfg["BOARD_VECTORS_BASE"], cfg["BOARD_VECTORS_SIZE"], "MPU_NORMAL_WB", "vectors (ATCM)"),
        (c_base, c_size, "MPU_NORMAL_WB", "carveout image"),
        (c_base + c_size - unc, unc, "MPU_NORMAL_NC", "carveout uncached top (trace)"),
        (cfg["BOARD_OCM_BASE"], cfg["BOARD_OCM_SIZE"], "MPU_NORMAL_NC",
         "OCM (amp_lib)"),
    ]
    seen: set[tuple[int, int]] = set()
    for n in devices:
        for r in n.regs:
            b, s = _region(r.addr, r.size)
            if (b, s) not in seen:
                seen.add((b, s))
                regions.append((b, s, "MPU_DEVICE", n.path))
    for b, s, _, what in regions:
        if not _pow2(s) or b % s:
            fail(ocm, f"MPU region {what} [{b:#x} +{s:#x}) is not a power of two aligned to its size")
    if len(regions) + GUARD_REGIONS > MPU_REGIONS:
        fail(ocm, f"{len(regions)} MPU regions and the stack guard: the R5 has {MPU_REGIONS}")
    cfg["__MEMPROT_MACRO__"] = ("BOARD_MPU_REGIONS", "MPU regions, lowest priority first")
    cfg["__LD_EXTRA__"] = [
        f"MEMORY {{ VECTORS (rx) : ORIGIN = 0x{cfg['BOARD_VECTORS_BASE']:08x}, "
        f"LENGTH = 0x{cfg['BOARD_VECTORS_SIZE']:08x} }}",
    ]
    return regions
