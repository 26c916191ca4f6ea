/* SPDX-License-Identifier: MIT */
/*
 * pmccntr.c - the R5 platform's time base (timebase.h): the core's own PMU
 * cycle counter, at the core clock (the servo devicetree's cpu
 * clock-frequency, BOARD_CPU_HZ), no divider. 32 bits wide: timebase_now()
 * extends it to 64 bits, which needs a call at least once per wrap (4.3 s
 * at 1 GHz); the background loop's statistics call it every
 * BOARD_STATS_CYCLES cycles.
 */
#include "arch.h"
#include "board.h"
#include "timebase.h"

#define PMCR_E (1u << 0)	/* counters enabled */
#define PMCR_C (1u << 2)	/* cycle counter reset */
#define PMCR_D (1u << 3)	/* cycle counter counts every 64th cycle */
#define PMCNTEN_C (1u << 31)

static uint32_t wraps, last;

static uint32_t pmccntr(void)
{
	return CP15_READ(0, c9, c13, 0);
}

int timebase_init(uint32_t *prescaler)
{
	uint32_t pmcr = CP15_READ(0, c9, c12, 0);

	pmcr = (pmcr | PMCR_E | PMCR_C) & ~PMCR_D;
	CP15_WRITE(0, c9, c12, 0, pmcr);
	CP15_WRITE(0, c9, c12, 1, PMCNTEN_C);	/* PMCNTENSET */
	isb();
	wraps = 0;
	last = pmccntr();
	*prescaler = 0;
	return 0;
}

int timebase_changed(void)
{
	return 0;
}

uint64_t timebase_now(void)
{
	uint32_t flags = irq_save();
	uint32_t now = pmccntr();
	uint64_t t;

	if (now < last)
		wraps++;
	last = now;
	t = ((uint64_t)wraps << 32) | now;
	irq_restore(flags);
	return t;
}

uint32_t timebase_now32(void)
{
	return pmccntr();
}

/* amp_lib bare-metal port hook (AMP_BOARD_TICKS_PER_US in board.h). */
uint32_t amp_board_ticks(void)
{
	return pmccntr();
}
