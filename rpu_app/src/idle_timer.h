/* SPDX-License-Identifier: MIT */
#ifndef RPU_IDLE_TIMER_H
#define RPU_IDLE_TIMER_H

#include <stdint.h>

/*
 * The idle wake: CPU1's private timer (board idle-timer, PPI, banked)
 * interrupts every idle-wake-us at the lowest priority in use, so the
 * background loop's wfi returns even when no cycle interrupt comes (one
 * lost or disabled at the GIC, the TTC stopped) and a STOP from the driver
 * is seen within that time. The handler only counts.
 */
int idle_timer_start(void);	/* 0, or -1 if the interrupt cannot be registered */
void idle_timer_stop(void);	/* before parking: no timer left running */
uint32_t idle_timer_wakes(void);

#endif
