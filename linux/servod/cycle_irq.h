/* SPDX-License-Identifier: MIT */
/*
 * cycle_irq.h - the cycle interrupt: TTC1 counter 1's interval event,
 * delivered through the UIO device "cycle-interrupt" (docs/cycle.md,
 * section 1). The device maps counter 1's clear-on-read interrupt
 * register; servod acknowledges its own flag, re-enables the line (write
 * 1) and reads its wake-up latency from the counter, which restarts at
 * every interval event.
 */
#ifndef SERVOD_CYCLE_IRQ_H
#define SERVOD_CYCLE_IRQ_H

#include <stdint.h>

struct servod;

struct cycle_irq {
	int fd;				/* the UIO device, -1 until opened */
	volatile uint8_t *ttc;		/* TTC registers, addressed from the TTC base */
	uint32_t ttc_hz;		/* the TTC's input clock */
};

/* One wake-up. */
struct cycle_wake {
	uint32_t count;		/* UIO event count */
	uint64_t t_ns;		/* wake-up time (CLOCK_MONOTONIC) */
	uint32_t lat_ns;	/* interval event to wake-up, from counter 1 */
};

/* Opens and maps the device: 0, or -1. */
int cycle_irq_open(struct servod *sd, struct cycle_irq *irq, uint32_t ttc_hz);
/*
 * Waits up to 100 ms for the next interval event; acknowledges it and
 * re-enables the line: 0 and *w, or -1 (nothing within 100 ms: the flag
 * is acknowledged and the line re-armed all the same, since a servod that
 * died between an interrupt and its re-enable leaves it disabled).
 * Cycle thread only.
 */
int cycle_irq_wait(struct servod *sd, struct cycle_irq *irq, struct cycle_wake *w);

#endif
