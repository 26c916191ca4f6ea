/* SPDX-License-Identifier: MIT */
#ifndef RPU_GTIMER_H
#define RPU_GTIMER_H

#include <stdint.h>

/*
 * A9 global timer: shared by both cores and owned by Linux (its
 * clocksource; Linux 6.1 on this board runs it with prescaler 1). Only
 * read here. All values returned are in NOMINAL ticks of the devicetree's
 * clock-frequency (BOARD_GTIMER_HZ, i.e. the prescaler-0 rate): the raw
 * count is multiplied by (prescaler + 1), so figures and amp_lib's
 * AMP_BOARD_TICKS_PER_US stay right whatever prescaler Linux chose.
 */
/* Read the control register: 0 running, 1 stopped. *prescaler set. */
int gtimer_init(uint32_t *prescaler);
uint64_t gtimer_now(void);
/* Low 32 bits of gtimer_now() (continuous modulo 2^32), one MMIO read. */
uint32_t gtimer_now32(void);
/* 1 if the prescaler differs from the one seen by gtimer_init(). */
int gtimer_changed(void);

#endif
