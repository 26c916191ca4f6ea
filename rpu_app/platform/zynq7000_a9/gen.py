# SPDX-License-Identifier: MIT
"""The Zynq-7000 A9 platform's part of rpu_app's board generation
(rpu_app/scripts/gen_board_header.py loads it for an arm,cortex-a9 servo
CPU): the A9 global timer as time base, CPU1's private timer as the idle
wake, the MMU's 1 MiB section map, the cooperative stop."""

from __future__ import annotations

from typing import Any, Callable

CPU_COMPATIBLE = "arm,cortex-a9"
NAME = "zynq7000_a9"
HAS_VBAR = True
GIC_OWNED = False        # the distributor is Linux's: never enabled here
GIC_IDS = 96             # the A9 GIC's interrupt IDs: 0..95
STOP_CONTRACT = True     # STOP / RUN! / PRKD words, park loop, boot register
SLCR = True              # the UART clock gate is checked in the SLCR
SECTION = 1 << 20        # MMU section (1 MiB)


def check_carveout(carve: Any, servo: Any, base: int, size: int, unc: int, fail: Callable[..., Any]) -> None:
    if base % SECTION or size % SECTION:
        fail(carve, "carveout must be 1 MiB aligned (MMU sections)")
    if unc % SECTION or not 0 < unc < size:
        fail(servo, "uncached-size must be a non-zero multiple of 1 MiB below the carveout size")


def timers(edt: Any, cpu: Any, servo: Any, put: Callable[..., None], fail: Callable[..., Any],
           prop: Callable[..., Any], one_reg: Callable[..., Any], gic_id: Callable[..., Any]) -> list[Any]:
    """The time base (the global timer, shared, Linux's) and the idle wake
    (CPU1's private timer). Returns the device nodes to map."""
    gt = prop(servo, "global-timer")
    put("BOARD_GTIMER_BASE", one_reg(gt)[0], gt.path)
    gt_hz = prop(gt, "clock-frequency")
    if gt_hz % 1_000_000:
        fail(gt, "clock-frequency must be a whole number of MHz")
    put("BOARD_GTIMER_HZ", gt_hz)
    put("BOARD_TIMEBASE_TICKS_PER_US", gt_hz // 1_000_000, "the global timer")

    twd = prop(servo, "idle-timer")
    put("BOARD_TWD_BASE", one_reg(twd)[0], twd.path)
    twd_hz = prop(twd, "clock-frequency")
    wake_us = prop(servo, "idle-wake-us")
    if not 100 <= wake_us <= 1_000_000:
        fail(servo, "idle-wake-us must be 100..1000000")
    twd_irq, _ = gic_id(twd, 0)
    if not 16 <= twd_irq < 32:
        fail(twd, "the private timer's interrupt must be a PPI")
    put("BOARD_TWD_IRQ", twd_irq, "GIC ID (PPI, banked per CPU)")
    put("BOARD_IDLE_WAKE_LOAD", twd_hz // 1_000_000 * wake_us - 1,
        f"private timer reload: {wake_us} us")
    return [gt]


def memory_map(cfg: dict[str, Any], carve: Any, ocm: Any, devices: list[Any],
               fail: Callable[..., Any]) -> list[tuple[int, int, str, str]]:
    """MMU sections: the carveout (image cacheable, top non-cacheable), OCM
    non-cacheable, the 1 MiB sections of every device the firmware uses."""
    c_base, c_size = cfg["BOARD_CARVEOUT_BASE"], cfg["BOARD_CARVEOUT_SIZE"]
    unc = cfg["BOARD_UNCACHED_SIZE"]
    o_base, o_size = cfg["BOARD_OCM_BASE"], cfg["BOARD_OCM_SIZE"]
    dev_sections: dict[int, str] = {}
    for n in devices:
        for r in n.regs:
            for s in range(r.addr // SECTION, (r.addr + r.size - 1) // SECTION + 1):
                dev_sections.setdefault(s * SECTION, n.path)
    ocm_sections = sorted({s * SECTION for s in range(o_base // SECTION, (o_base + o_size - 1) // SECTION + 1)})
    for s in ocm_sections:
        if s in dev_sections:
            fail(ocm, f"shares MMU section {s:#x} with device {dev_sections[s]}")
    mmu = [(c_base, c_size - unc, "MMU_NORMAL_WB", "carveout image"),
           (c_base + c_size - unc, unc, "MMU_NORMAL_NC", "carveout uncached top")]
    for s in ocm_sections:
        mmu.append((s, SECTION, "MMU_NORMAL_NC", "OCM (amp_lib, stop words, boot register)"))
    for s, path in sorted(dev_sections.items()):
        mmu.append((s, SECTION, "MMU_DEVICE", path))
    cfg["__MEMPROT_MACRO__"] = ("BOARD_MMU_REGIONS", "MMU regions in 1 MiB sections")
    return mmu
