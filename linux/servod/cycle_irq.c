// SPDX-License-Identifier: MIT
/* cycle_irq.c - the cycle interrupt through UIO (cycle_irq.h). */
#define _GNU_SOURCE
#include <errno.h>
#include <poll.h>
#include <string.h>
#include <unistd.h>

#include "context.h"
#include "servoamp/cadence_ttc.h"

/* Linux's counter of the cycle TTC (docs/cycle.md; servo.dts:
 * linux-cycle-counter = <1>): its interrupt register is the UIO node's reg. */
#define LINUX_COUNTER 1

static uint32_t ttc_rd(const struct cycle_irq *irq, uint32_t off)
{
	return *(volatile uint32_t *)(irq->ttc + off);
}

/* Counter 1's tick in ns, Q16 (its prescaler as the firmware set it). */
static uint32_t ns_per_tick_q16(const struct cycle_irq *irq)
{
	uint32_t clk = ttc_rd(irq, TTC_CLK_CTRL(LINUX_COUNTER));
	uint64_t div = ttc_clk_div(clk);

	return (uint32_t)((div * 1000000000ull * 65536u) / irq->ttc_hz);
}

int cycle_irq_open(struct servod *sd, struct cycle_irq *irq, uint32_t ttc_hz)
{
	uint32_t size, offs;

	irq->ttc_hz = ttc_hz;
	irq->fd = uio_open(sd, "cycle-interrupt", &irq->ttc, &size, &offs);
	if (irq->fd < 0)
		return -1;
	irq->ttc += offs;	/* the node's reg is counter 1's interrupt register */
	irq->ttc -= TTC_ISR(LINUX_COUNTER);	/* ... registers addressed from the TTC base */
	return 0;
}

/* Acknowledge our flag (clear on read) and re-enable the line. */
static void ack_and_rearm(struct servod *sd, struct cycle_irq *irq)
{
	uint32_t one = 1;

	(void)ttc_rd(irq, TTC_ISR(LINUX_COUNTER));
	if (write(irq->fd, &one, 4) != 4)
		log_rt(sd, "uio: re-enable failed: %s", strerror(errno));
}

int cycle_irq_wait(struct servod *sd, struct cycle_irq *irq, struct cycle_wake *w)
{
	struct pollfd pfd = { irq->fd, POLLIN, 0 };
	uint32_t ticks;

	if (poll(&pfd, 1, 100) <= 0) {
		/* idempotent in the UIO driver (linux/uio) */
		ack_and_rearm(sd, irq);
		return -1;
	}
	if (read(irq->fd, &w->count, 4) != 4)
		return -1;
	w->t_ns = mono_now_ns();
	ticks = ttc_rd(irq, TTC_CNT_VAL(LINUX_COUNTER)) & TTC_CNT_MASK;
	ack_and_rearm(sd, irq);
	w->lat_ns = (uint32_t)(((uint64_t)ticks * ns_per_tick_q16(irq)) >> 16);
	return 0;
}
