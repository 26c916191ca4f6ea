/* SPDX-License-Identifier: MIT */
#ifndef RPU_TIMEBASE_H
#define RPU_TIMEBASE_H

#include <stdint.h>

/*
 * The platform's free-running time base (platform/<soc>/), in ticks of
 * BOARD_TIMEBASE_TICKS_PER_US per microsecond (board_config.h, from the
 * servo devicetree):
 *   zynq7000_a9  the A9 global timer, shared with Linux and owned by it
 *                (its clocksource; only read here). Values are in NOMINAL
 *                ticks of the devicetree's clock-frequency (the
 *                prescaler-0 rate): the raw count is multiplied by
 *                (prescaler + 1), whatever prescaler Linux chose.
 *   zynqmp_r5    the R5's own PMU cycle counter (PMCCNTR, the core clock),
 *                extended to 64 bits in software; no prescaler.
 */
/* 0 running, 1 stopped (its owner has not started it). *prescaler set. */
int timebase_init(uint32_t *prescaler);
uint64_t timebase_now(void);
/* Low 32 bits of timebase_now() (continuous modulo 2^32), one read. */
uint32_t timebase_now32(void);
/* 1 if the prescaler differs from the one seen by timebase_init(). */
int timebase_changed(void);

#endif
