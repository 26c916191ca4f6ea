/* SPDX-License-Identifier: MIT */
#ifndef RPU_TTC_H
#define RPU_TTC_H

#include <stdint.h>

/* The cycle timer: one counter of a Cadence TTC in interval mode. */
void ttc_cycle_start(void);
void ttc_cycle_stop(void);
/* IDT clear function: reads (clears) the counter's interrupt register. */
void ttc_cycle_clear(void *arg);
/* Nanoseconds since the last interval event (the "expected fire point"). */
uint32_t ttc_cycle_since_fire_ns(void *arg);

#endif
