/* SPDX-License-Identifier: MIT */
/*
 * ttc.c - the cycle time base: two counters of the TTC named by the
 * devicetree, programmed here with the same interval (the firmware owns
 * the TTC's configuration):
 *
 *   counter BOARD_CYCLE_COUNTER        -> this core's cycle interrupt
 *                                         (cleared here, ttc_cycle_clear)
 *   counter BOARD_LINUX_CYCLE_COUNTER  -> Linux's cycle interrupt (CPU0;
 *                                         Linux clears it through UIO)
 *
 * Linux's counter is started first and this core's counter half a period
 * later: both cores get exactly one interrupt per cycle from a common time
 * base, Linux leading by T/2, so that Linux's commands of cycle n are
 * published before the servo reads them and the servo's feedback of cycle
 * n-1 is complete before Linux reads it (docs/cycle.md).
 *
 * Linux's counter stands for the FPGA's cycle timer, which does not stop
 * when the servo core does: a firmware stop (servo_quiesce_and_park) leaves
 * it running, and a restarted firmware takes up its period
 * (ttc_running_period_us) and starts only its own counter, in phase with
 * it. Linux's cycle goes on through a firmware restart without a gap.
 *
 * Interval mode, 16-bit counter, prescaler chosen at run time for the
 * period (the cycle_period_us parameter). The counter restarts from 0 at
 * every interval event, so its value read in the handler is the time
 * elapsed since the interrupt was raised: the entry latency.
 *
 * Interrupt: level, held while (ISR & IER) != 0; the ISR is clear-on-read
 * (as QEMU's hw/timer/cadence_ttc.c and the Zynq TRM describe it).
 */
#include "arch.h"
#include "board.h"
#include "servoamp/cadence_ttc.h"
#include "ttc.h"

#define N BOARD_CYCLE_COUNTER
#define L BOARD_LINUX_CYCLE_COUNTER
#define X (3u - N - L)		/* the third counter: debug only (ttc_stray_start) */
#define REG(off) (BOARD_TTC_BASE + (off))

/* Set by ttc_cycle_start (no initialised data in this firmware). */
static uint32_t ns_per_tick_q16;
static uint32_t period_ns;

int ttc_setting(uint32_t period_us, struct ttc_setting *s)
{
	for (int ps = -1; ps < 16; ps++) {
		uint32_t clk = ps < 0 ? 0u : TTC_CLK_PS(ps);
		uint64_t div = ttc_clk_div(clk);
		uint64_t ticks = ((uint64_t)BOARD_TTC_HZ * period_us + div * 500000u) / (div * 1000000u);

		if (ticks >= 2u && ticks <= 0x10000u) {
			s->clk = clk;
			s->interval = (uint32_t)ticks - 1u;
			s->ns_per_tick_q16 = (uint32_t)((div * 1000000000ull * 65536u + BOARD_TTC_HZ / 2u) / BOARD_TTC_HZ);
			s->period_ns = (uint32_t)(ticks * div * 1000000000ull / BOARD_TTC_HZ);
			return 0;
		}
	}
	return -1;
}

static void counter_off(uint32_t n)
{
	mmio_write32(REG(TTC_CNT_CTRL(n)), TTC_CNT_DIS | TTC_CNT_WAVE_DIS);
	mmio_write32(REG(TTC_IER(n)), 0);
	(void)mmio_read32(REG(TTC_ISR(n)));
}

/* Linux's counter runs (enabled, interval mode, its interrupt on) with
 * exactly the setting s: then it is left alone. */
static int linux_counter_runs(const struct ttc_setting *s)
{
	uint32_t ctrl = mmio_read32(REG(TTC_CNT_CTRL(L)));

	return !(ctrl & TTC_CNT_DIS) && (ctrl & TTC_CNT_INTERVAL) &&
	       (mmio_read32(REG(TTC_IER(L))) & TTC_INT_INTERVAL) &&
	       mmio_read32(REG(TTC_CLK_CTRL(L))) == s->clk &&
	       (mmio_read32(REG(TTC_INTERVAL(L))) & TTC_CNT_MASK) == s->interval;
}

uint32_t ttc_running_period_us(void)
{
	uint32_t clk = mmio_read32(REG(TTC_CLK_CTRL(L)));
	uint64_t ticks = (uint64_t)(mmio_read32(REG(TTC_INTERVAL(L))) & TTC_CNT_MASK) + 1u;
	uint64_t div = ttc_clk_div(clk);
	uint64_t us = (ticks * div * 1000000u + BOARD_TTC_HZ / 2u) / BOARD_TTC_HZ;
	struct ttc_setting s;

	if (!us || us > 0xffffffffu || ttc_setting((uint32_t)us, &s) || !linux_counter_runs(&s))
		return 0;
	return (uint32_t)us;
}

int ttc_cycle_start(uint32_t period_us)
{
	struct ttc_setting s;
	uint32_t flags, half, prev;
	int keep;

	if (ttc_setting(period_us, &s))
		return -1;
	flags = irq_save();
	counter_off(N);
	/* Linux's counter is the FPGA's cycle timer: running at this period
	 * (a firmware restart), it goes on; Linux misses no cycle. */
	keep = linux_counter_runs(&s);
	if (!keep)
		counter_off(L);
	ns_per_tick_q16 = s.ns_per_tick_q16;
	period_ns = s.period_ns;
	mmio_write32(REG(TTC_CLK_CTRL(N)), s.clk);
	mmio_write32(REG(TTC_INTERVAL(N)), s.interval);
	mmio_write32(REG(TTC_IER(N)), TTC_INT_INTERVAL);
	if (!keep) {
		mmio_write32(REG(TTC_CLK_CTRL(L)), s.clk);
		mmio_write32(REG(TTC_INTERVAL(L)), s.interval);
		mmio_write32(REG(TTC_IER(L)), TTC_INT_INTERVAL);
		mmio_write32(REG(TTC_CNT_CTRL(L)), TTC_CNT_INTERVAL | TTC_CNT_RST | TTC_CNT_WAVE_DIS);
	}
	/* This core's counter starts when Linux's crosses half its interval
	 * (from below: a running counter may be past it now). */
	half = s.interval / 2u;
	prev = mmio_read32(REG(TTC_CNT_VAL(L))) & TTC_CNT_MASK;
	for (uint32_t i = 0; i < 10000000u; i++) {
		uint32_t v = mmio_read32(REG(TTC_CNT_VAL(L))) & TTC_CNT_MASK;

		if (v >= half && prev < half)
			break;
		prev = v;
	}
	mmio_write32(REG(TTC_CNT_CTRL(N)), TTC_CNT_INTERVAL | TTC_CNT_RST | TTC_CNT_WAVE_DIS);
	irq_restore(flags);
	return 0;
}

void ttc_servo_stop(void)
{
	counter_off(N);
	counter_off(X);
}

uint32_t ttc_stray_start(void)
{
	counter_off(X);
	mmio_write32(REG(TTC_CLK_CTRL(X)), 0);
	mmio_write32(REG(TTC_INTERVAL(X)), 0x1000u);
	mmio_write32(REG(TTC_IER(X)), TTC_INT_INTERVAL);
	mmio_write32(REG(TTC_CNT_CTRL(X)), TTC_CNT_INTERVAL | TTC_CNT_RST | TTC_CNT_WAVE_DIS);
	/* the TTC's three interrupts are consecutive GIC IDs */
	return BOARD_CYCLE_IRQ - N + X;
}

uint32_t ttc_period_ns(void)
{
	return period_ns ? period_ns : BOARD_CYCLE_PERIOD_NS;
}

void ttc_cycle_clear(void *arg)
{
	(void)arg;
	(void)mmio_read32(REG(TTC_ISR(N)));
}

uint32_t ttc_cycle_since_fire_ns(void *arg)
{
	uint32_t ticks = mmio_read32(REG(TTC_CNT_VAL(N))) & TTC_CNT_MASK;

	(void)arg;
	return (uint32_t)(((uint64_t)ticks * (ns_per_tick_q16 ? ns_per_tick_q16 : BOARD_CYCLE_NS_PER_TICK_Q16)) >> 16);
}
