/* SPDX-License-Identifier: MIT */
/*
 * mmu.c - the A9 platform's memory protection (memprot.h): a flat
 * (VA == PA) first-level section map and cache enable.
 *
 * The map is generated from the devicetree (BOARD_MMU_REGIONS): only the
 * regions the firmware uses are mapped; everything else faults, so a stray
 * pointer into Linux's memory is caught instead of corrupting it.
 *
 *  carveout image  Normal, inner write-back write-allocate, OUTER
 *                  NON-CACHEABLE, non-shareable, executable. Only this
 *                  core's L1 ever holds these lines: the PL310 L2 (owned by
 *                  Linux) never does, so Linux's uncached view of the
 *                  carveout is correct once this core cleaned its L1, which
 *                  cpu_park does on every stop.
 *  carveout top    Normal non-cacheable, shareable, execute-never: the
 *                  remoteproc trace buffer, read by Linux at any time.
 *  OCM             Normal non-cacheable, shareable, execute-never: the
 *                  amp_lib region and the stop/status words; amp_lib is
 *                  built with AMP_CFG_OCM_CACHED=0 to match, and orders its
 *                  accesses with DMB.
 *  devices         Shareable Device, execute-never.
 *
 * Stack guard: the 1 MiB section that holds the SVC stack's guard page
 * (servo.ld, __stack_guard_start/end) is mapped through a second-level
 * table of 4 KiB small pages with the section's own attributes, except the
 * guard pages, whose entries are faults (no access at any level). An SVC
 * stack overflow therefore takes a data abort at the guard (fault.c names
 * it) instead of rewriting the translation tables below the stacks.
 *
 * Translation-table walks are non-cacheable (TTBR0 RGN/IRGN = 0) and the
 * table is written while the D-cache is still off, so no maintenance of
 * the table itself is needed. Domain 0, client (permissions checked), full
 * access at PL1. Secure (NS = 0) like the core itself.
 */
#include <stdint.h>

#include "arch.h"
#include "board.h"
#include "memprot.h"

#define SECTION_SHIFT 20
#define L1_ENTRIES    4096u

/* Short-descriptor section bits. */
#define SD_SECTION  0x2u
#define SD_B        (1u << 2)
#define SD_C        (1u << 3)
#define SD_XN       (1u << 4)
#define SD_AP_RW    (3u << 10)	/* AP[1:0] = 11, AP[2] = 0: RW at any PL */
#define SD_TEX(x)   ((uint32_t)(x) << 12)
#define SD_S        (1u << 16)
#define SD_NG       (1u << 17)
#define SD_AP2      (1u << 15)

/* Short-descriptor first-level page-table entry, small-page bits. */
#define PT_L1_COARSE 0x1u
#define SP_PAGE      0x2u	/* small page; bit 0 is XN */
#define SP_XN        (1u << 0)
#define SP_B         (1u << 2)
#define SP_C         (1u << 3)
#define SP_AP_SHIFT  4	/* AP[1:0] */
#define SP_TEX_SHIFT 6
#define SP_AP2       (1u << 9)
#define SP_S         (1u << 10)
#define SP_NG        (1u << 11)
#define PAGE_SHIFT   12
#define L2_ENTRIES   256u

/* Attribute sets used by BOARD_MMU_REGIONS. */
#define MMU_NORMAL_WB (SD_SECTION | SD_AP_RW | SD_TEX(4) | SD_B)	/* inner WB-WA, outer NC */
#define MMU_NORMAL_NC (SD_SECTION | SD_AP_RW | SD_TEX(1) | SD_S | SD_XN)
#define MMU_DEVICE    (SD_SECTION | SD_AP_RW | SD_B | SD_XN)	/* shareable device */

#define SCTLR_M (1u << 0)
#define SCTLR_C (1u << 2)
#define SCTLR_Z (1u << 11)
#define SCTLR_I (1u << 12)

static uint32_t l1_table[L1_ENTRIES] __attribute__((aligned(16384), section(".mmu_table")));
static uint32_t l2_guard_table[L2_ENTRIES] __attribute__((aligned(1024), section(".mmu_l2_table")));

/* servo.ld: the no-access page(s) directly below the SVC stack. */
extern uint32_t __stack_guard_start[], __stack_guard_end[];

void dcache_setway(uint32_t op);

static void map(uint32_t base, uint32_t size, uint32_t attr)
{
	for (uint32_t s = base >> SECTION_SHIFT; s < ((base + (size - 1u)) >> SECTION_SHIFT) + 1u; s++)
		l1_table[s] = (s << SECTION_SHIFT) | attr;
}

/* Same memory type, permissions and XN as a section descriptor, for a
 * small page. */
static uint32_t small_page_attr(uint32_t sd)
{
	uint32_t a = SP_PAGE;

	a |= sd & (SD_B | SD_C);
	if (sd & SD_XN)
		a |= SP_XN;
	a |= ((sd >> 10) & 3u) << SP_AP_SHIFT;
	a |= ((sd >> 12) & 7u) << SP_TEX_SHIFT;
	if (sd & SD_AP2)
		a |= SP_AP2;
	if (sd & SD_S)
		a |= SP_S;
	if (sd & SD_NG)
		a |= SP_NG;
	return a;
}

/* Replace the section holding the stack guard by a second-level table:
 * 4 KiB pages as the section was, guard pages faulting. */
static void map_stack_guard(void)
{
	uint32_t g0 = (uint32_t)(uintptr_t)__stack_guard_start;
	uint32_t g1 = (uint32_t)(uintptr_t)__stack_guard_end;
	uint32_t sec = g0 >> SECTION_SHIFT;
	uint32_t sd = l1_table[sec];
	uint32_t attr = small_page_attr(sd);

	if ((sd & 3u) != SD_SECTION)
		return;	/* not mapped: every page faults already */
	for (uint32_t i = 0; i < L2_ENTRIES; i++) {
		uint32_t va = (sec << SECTION_SHIFT) | (i << PAGE_SHIFT);

		l2_guard_table[i] = (va >= g0 && va < g1) ? 0u : (va | attr);
	}
	/* coarse table, domain 0, Secure (NS = 0) */
	l1_table[sec] = (uint32_t)(uintptr_t)l2_guard_table | PT_L1_COARSE;
}

uint32_t memprot_stack_guard_start(void)
{
	return (uint32_t)(uintptr_t)__stack_guard_start;
}

uint32_t memprot_stack_guard_end(void)
{
	return (uint32_t)(uintptr_t)__stack_guard_end;
}

const char *memprot_describe(void)
{
	return "on (L1 I+D, carveout inner-WB, OCM/trace non-cacheable)";
}

int memprot_enabled(void)
{
	return (CP15_READ(0, c1, c0, 0) & SCTLR_M) != 0;
}

void memprot_init(void)
{
	uint32_t sctlr;

	/* Caches are off here (start.S): discard whatever L1 holds (random
	 * after reset, cleaned by cpu_park after a stop) before use. */
	CP15_WRITE(0, c7, c5, 0, 0);	/* ICIALLU */
	CP15_WRITE(0, c7, c5, 6, 0);	/* BPIALL */
	CP15_WRITE(0, c8, c7, 0, 0);	/* TLBIALL */
	dcache_setway(0);

	for (uint32_t i = 0; i < L1_ENTRIES; i++)
		l1_table[i] = 0;	/* fault */
#define X(base, size, attr) map((base), (size), (attr));
	BOARD_MMU_REGIONS(X)
#undef X
	map_stack_guard();
	dsb();

	CP15_WRITE(0, c2, c0, 2, 0);			/* TTBCR: N = 0, TTBR0 only */
	CP15_WRITE(0, c2, c0, 0, (uint32_t)(uintptr_t)l1_table);	/* walks NC */
	CP15_WRITE(0, c3, c0, 0, 0x1u);			/* DACR: domain 0 client */
	CP15_WRITE(0, c8, c7, 0, 0);			/* TLBIALL */
	dsb();
	isb();

	sctlr = CP15_READ(0, c1, c0, 0);
	sctlr |= SCTLR_M | SCTLR_C | SCTLR_I | SCTLR_Z;
	CP15_WRITE(0, c1, c0, 0, sctlr);
	isb();
}
