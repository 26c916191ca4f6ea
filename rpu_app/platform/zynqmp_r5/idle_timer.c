/* SPDX-License-Identifier: MIT */
/*
 * idle_timer.c - the R5 platform has no idle wake (idle_timer.h). On the
 * A9 it bounds the background loop's wfi so a STOP in the control word is
 * seen without cycle interrupts; Linux's upstream R5 driver has no stop
 * word (it powers the core down), so there is nothing to poll for.
 */
#include "idle_timer.h"

int idle_timer_start(void)
{
	return 0;
}

void idle_timer_stop(void)
{
}

uint32_t idle_timer_wakes(void)
{
	return 0;
}
