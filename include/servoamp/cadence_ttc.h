/* SPDX-License-Identifier: MIT */
/*
 * cadence_ttc.h - the register map of the Cadence triple timer counter
 * (TTC) that gives both cores their cycle interrupt (docs/cycle.md): the
 * firmware programs two of its counters (rpu_app/src/ttc.c), servod reads
 * Linux's counter through UIO (linux/servod/cycle_irq.c). As in the Zynq-7000
 * TRM (ug585, appendix B.32 "Triple Timer Counter") and QEMU's
 * hw/timer/cadence_ttc.c. Offsets from the TTC's base; n = counter 0..2.
 * Freestanding C11 (the firmware has no libc).
 */
#ifndef SERVOAMP_CADENCE_TTC_H
#define SERVOAMP_CADENCE_TTC_H

#include <stdint.h>

#define TTC_CLK_CTRL(n)  (0x00u + 4u * (n))	/* clock control: prescaler */
#define TTC_CNT_CTRL(n)  (0x0cu + 4u * (n))	/* counter control */
#define TTC_CNT_VAL(n)   (0x18u + 4u * (n))	/* counter value (16 bits) */
#define TTC_INTERVAL(n)  (0x24u + 4u * (n))	/* interval (16 bits) */
#define TTC_ISR(n)       (0x54u + 4u * (n))	/* interrupt register, clear on read */
#define TTC_IER(n)       (0x60u + 4u * (n))	/* interrupt enable */

/* clock control */
#define TTC_CLK_PS_EN		(1u << 0)	/* prescaler on */
#define TTC_CLK_PS(ps)		(TTC_CLK_PS_EN | ((uint32_t)(ps) << 1))	/* divide by 2^(ps+1), ps 0..15 */

/* counter control */
#define TTC_CNT_DIS		(1u << 0)
#define TTC_CNT_INTERVAL	(1u << 1)	/* interval mode (else overflow) */
#define TTC_CNT_RST		(1u << 4)	/* restart from 0 */
#define TTC_CNT_WAVE_DIS	(1u << 5)

/* interrupt register / enable */
#define TTC_INT_INTERVAL	(1u << 0)

#define TTC_CNT_MASK		0xffffu		/* the counters are 16 bits wide */

/* The input clock's divider a clock control value selects: 1 without the
 * prescaler, else 2^(ps+1). */
static inline uint32_t ttc_clk_div(uint32_t clk_ctrl)
{
	return (clk_ctrl & TTC_CLK_PS_EN) ? 2u << ((clk_ctrl >> 1) & 0xfu) : 1u;
}

#endif /* SERVOAMP_CADENCE_TTC_H */
