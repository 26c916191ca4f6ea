/* SPDX-License-Identifier: MIT */
/*
 * ttc.c - cycle interrupt source: counter BOARD_CYCLE_COUNTER of the TTC
 * named by the devicetree, in interval mode, prescaler and interval
 * computed by the generator (16-bit counter). The counter restarts from 0
 * at every interval event, so its value read in the handler is exactly the
 * time elapsed since the interrupt was raised: that is the entry latency.
 *
 * Interrupt: level, held while (ISR & IER) != 0; the ISR is clear-on-read
 * (as QEMU's hw/timer/cadence_ttc.c and the Zynq TRM describe it).
 */
#include "arch.h"
#include "board.h"
#include "ttc.h"

#define TTC_CLK_CTRL(n)  (0x00u + 4u * (n))
#define TTC_CNT_CTRL(n)  (0x0cu + 4u * (n))
#define TTC_CNT_VAL(n)   (0x18u + 4u * (n))
#define TTC_INTERVAL(n)  (0x24u + 4u * (n))
#define TTC_ISR(n)       (0x54u + 4u * (n))
#define TTC_IER(n)       (0x60u + 4u * (n))

#define CLK_PS_EN       (1u << 0)
#define CNT_DIS         (1u << 0)
#define CNT_INTERVAL    (1u << 1)
#define CNT_RST         (1u << 4)
#define CNT_WAVE_DIS    (1u << 5)
#define INT_INTERVAL    (1u << 0)

#define N BOARD_CYCLE_COUNTER
#define REG(off) (BOARD_TTC_BASE + (off))

void ttc_cycle_start(void)
{
	mmio_write32(REG(TTC_CNT_CTRL(N)), CNT_DIS | CNT_WAVE_DIS);
	mmio_write32(REG(TTC_IER(N)), 0);
	(void)mmio_read32(REG(TTC_ISR(N)));
	mmio_write32(REG(TTC_CLK_CTRL(N)),
		     (BOARD_CYCLE_PS_EN ? CLK_PS_EN : 0u) | (BOARD_CYCLE_PS_V << 1));
	mmio_write32(REG(TTC_INTERVAL(N)), BOARD_CYCLE_INTERVAL);
	mmio_write32(REG(TTC_IER(N)), INT_INTERVAL);
	mmio_write32(REG(TTC_CNT_CTRL(N)), CNT_INTERVAL | CNT_RST | CNT_WAVE_DIS);
}

void ttc_cycle_stop(void)
{
	mmio_write32(REG(TTC_CNT_CTRL(N)), CNT_DIS | CNT_WAVE_DIS);
	mmio_write32(REG(TTC_IER(N)), 0);
	(void)mmio_read32(REG(TTC_ISR(N)));
}

void ttc_cycle_clear(void *arg)
{
	(void)arg;
	(void)mmio_read32(REG(TTC_ISR(N)));
}

uint32_t ttc_cycle_since_fire_ns(void *arg)
{
	uint32_t ticks = mmio_read32(REG(TTC_CNT_VAL(N))) & 0xffffu;

	(void)arg;
	return (uint32_t)(((uint64_t)ticks * BOARD_CYCLE_NS_PER_TICK_Q16) >> 16);
}
