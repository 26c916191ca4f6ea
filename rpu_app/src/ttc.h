/* SPDX-License-Identifier: MIT */
#ifndef RPU_TTC_H
#define RPU_TTC_H

#include <stdint.h>

/* The cycle time base: two counters of a Cadence TTC in interval mode,
 * one interrupt per core (this core's, and Linux's half a period ahead). */
struct ttc_setting {
	uint32_t clk;		/* clock control register value */
	uint32_t interval;	/* interval register (ticks - 1) */
	uint32_t ns_per_tick_q16;
	uint32_t period_ns;	/* what the counter really produces */
};
/* 0 and *s for a period in microseconds, -1 if the 16-bit counter cannot. */
int ttc_setting(uint32_t period_us, struct ttc_setting *s);
/* (Re)program and start both counters; -1 if the period is unreachable.
 * Linux's counter, already running at this period, is left as it is; this
 * core's counter starts half a period after Linux's. */
int ttc_cycle_start(uint32_t period_us);
/* This core's counter and the stray counter off; Linux's runs on (a stop
 * of the firmware: the cycle timer is the FPGA's, not this core's). */
void ttc_servo_stop(void);
/* The period (us) Linux's counter runs at, as ttc_setting() would program
 * it; 0 if it is stopped or programmed otherwise. */
uint32_t ttc_running_period_us(void);
/* Debug (SP_DEBUG_STRAY_IRQ): start the TTC counter used by neither cycle,
 * interval mode, its interrupt enabled and never cleared here; returns its
 * GIC ID. */
uint32_t ttc_stray_start(void);
uint32_t ttc_period_ns(void);
/* IDT clear function: reads (clears) this core's counter interrupt register. */
void ttc_cycle_clear(void *arg);
/* Nanoseconds since the last interval event (the "expected fire point"). */
uint32_t ttc_cycle_since_fire_ns(void *arg);

#endif
