/* SPDX-License-Identifier: MIT */
#include "arch.h"
#include "board.h"
#include "timebase.h"

#define GT_COUNTER_LO 0x00u
#define GT_COUNTER_HI 0x04u
#define GT_CONTROL    0x08u
#define GT_ENABLE     (1u << 0)
#define GT_PRESCALER(c) (((c) >> 8) & 0xffu)

static uint32_t mult;	/* prescaler + 1 */

int timebase_init(uint32_t *prescaler)
{
	uint32_t c = mmio_read32(BOARD_GTIMER_BASE + GT_CONTROL);

	mult = GT_PRESCALER(c) + 1u;
	*prescaler = GT_PRESCALER(c);
	return (c & GT_ENABLE) ? 0 : 1;
}

int timebase_changed(void)
{
	return GT_PRESCALER(mmio_read32(BOARD_GTIMER_BASE + GT_CONTROL)) + 1u != mult;
}

uint64_t timebase_now(void)
{
	uint32_t hi, lo, hi2;

	do {
		hi = mmio_read32(BOARD_GTIMER_BASE + GT_COUNTER_HI);
		lo = mmio_read32(BOARD_GTIMER_BASE + GT_COUNTER_LO);
		hi2 = mmio_read32(BOARD_GTIMER_BASE + GT_COUNTER_HI);
	} while (hi != hi2);
	return (((uint64_t)hi << 32) | lo) * mult;
}

uint32_t timebase_now32(void)
{
	/* low 32 bits of a product depend only on the low 32 bits */
	return mmio_read32(BOARD_GTIMER_BASE + GT_COUNTER_LO) * mult;
}

/* amp_lib bare-metal port hook (AMP_BOARD_TICKS_PER_US in board.h). */
uint32_t amp_board_ticks(void)
{
	return timebase_now32();
}
