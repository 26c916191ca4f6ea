/* SPDX-License-Identifier: MIT */
/*
 * main.c - rpu_app, the servoamp servo firmware on the second Cortex-A9.
 *
 * Start: MMU/caches, logger + banner, GIC CPU interface, interrupt
 * descriptor table (cycle interrupt from the TTC, nesting self-test SGI),
 * amp_lib link, "RUN!". Main loop: cooperative stop, attach retries,
 * statistics, UART draining, WFI between cycles.
 */
#include <stdint.h>
#include <string.h>

#include "arch.h"
#include "board.h"
#if HAVE_AMP_LIB
#include "app.h"
#include "axis.h"
#endif
#include "gic.h"
#include "timebase.h"
#include "idle_timer.h"
#include "irq.h"
#include "link.h"
#include "log.h"
#include "memprot.h"
#include "servo.h"
#include "ttc.h"
#include "uart.h"
#include "variant.h"

#include "rpu_version.h"	/* generated: RPU_VERSION, RPU_GIT, RPU_BUILD_DATE */
#ifndef CONFIG_MMU
#define CONFIG_MMU 1
#endif
#ifndef CONFIG_IDLE_WFI
#define CONFIG_IDLE_WFI 1
#endif

#define GIC_PMR 0xf0u		/* accept every priority above 0xf0 */
#define GIC_BPR 2u		/* group priority = bits [7:3]: 32 groups */
#define NS_PER_GT_TICK (1000u / BOARD_TIMEBASE_TICKS_PER_US)

extern uint32_t __stacks_start[], __svc_stack_top[], __svc_stack_bottom[];
extern char __image_end[];

/* Cycle state: written by the cycle handler, read by the main loop. */
static volatile uint32_t cycles;
static uint32_t last_gt;
static volatile uint32_t period_changed, last_period_ns;
static uint32_t period_min, period_max, overruns, missed;
static volatile uint32_t sgi_stamp, sgi_seen;
static uint32_t nest_ok, nest_fail;
/* The VFP half of the self-test (fpu_nest_probe, cpu.S): the SGI handler
 * computes fpu_work() from fpu_in; its result must equal the one computed
 * outside any interrupt, and the cycle handler's registers must come back. */
static volatile float fpu_in;	/* 1.7f, set at start (no .data) */
static volatile uint32_t fpu_res, fpu_ref;
static uint32_t fpu_ok, fpu_fail, fpu_fail_why;

uint32_t fpu_nest_probe(volatile uint32_t *sgir, uint32_t word, volatile uint32_t *seen);

static uint32_t fpu_bits(float f)
{
	uint32_t u;

	memcpy(&u, &f, sizeof(u));
	return u;
}

/* Dependent float operations, inexact on purpose (they set IXC). */
static float fpu_work(float x)
{
	float a = x, b = 1.0f / 3.0f, c = 0.0f;

	for (int i = 0; i < 8; i++) {
		c = c * 0.5f + a * b;
		a = a + b;
		b = b * 1.25f;
	}
	return c;
}
static uint64_t gt_start;
static struct gic_drain drain;	/* what the start found active (gic.h) */

static void nest_test_handler(void *arg)
{
	(void)arg;
	fpu_res = fpu_bits(fpu_work(fpu_in));
	sgi_seen++;
}

static uint32_t nest_test_latency(void *arg)
{
	(void)arg;
	return (timebase_now32() - sgi_stamp) * NS_PER_GT_TICK;
}

static int stop_requested(void);

static void cycle_handler(void *arg)
{
	uint32_t now = timebase_now32();
	uint32_t lat = ttc_cycle_since_fire_ns(0);
	uint32_t c = cycles;
	uint32_t pns = ttc_period_ns();

	/* The interval event's own time (handler entry minus the latency
	 * read from the counter, which restarted at the event): periods and
	 * missed events are counted between events, not between entries, so
	 * entry jitter is never taken for a lost event. */
	uint32_t fire = now - lat / NS_PER_GT_TICK;

	(void)arg;
	if (c && !period_changed) {
		uint32_t d = (fire - last_gt) * NS_PER_GT_TICK;

		if (d < period_min)
			period_min = d;
		if (d > period_max)
			period_max = d;
		if (d > pns + pns / 2u) {
			/* Late by more than half a period: interval events
			 * merged (the TTC flag is a level, cleared once). */
			overruns++;
			missed += (d + pns / 2u) / pns - 1u;
		}
	}
	period_changed = 0;
	last_gt = fire;
	cycles = c + 1u;
	/* STOP is honoured here too, not only in the background loop: a core
	 * whose cycle handlers run back to back (overloaded) or whose
	 * background loop starves for any other reason still parks. */
	if (stop_requested()) {
		log_printf("stop: STOP seen in the cycle handler after %u cycles\n", (unsigned)(c + 1u));
		servo_quiesce_and_park();
	}
	link_cycle(now, lat);

	/* Nesting self-test, once per statistics interval: a higher-priority
	 * SGI to this core must preempt this handler before it returns. */
	if ((c + 1u) % BOARD_STATS_CYCLES == BOARD_STATS_CYCLES / 2u) {
		uint32_t r;

		fpu_res = 0;
		sgi_stamp = timebase_now32();
		r = fpu_nest_probe(gic_sgir(), gic_sgi_self_word(BOARD_NEST_TEST_SGI), &sgi_seen);
		if (r == 10u) {
			nest_fail++;
		} else {
			nest_ok++;
			if (r == 0u && fpu_res == fpu_ref) {
				fpu_ok++;
			} else {
				fpu_fail++;
				fpu_fail_why = r ? r : 11u;	/* 11: the handler's own result wrong */
			}
		}
	}
	if (link_debug.overload) {	/* debug: as if this handler outlasted the period */
		link_debug.overload = 2;	/* in effect */
		gic_irq_pend(BOARD_CYCLE_IRQ);
	}
}

static uint32_t stack_used(uint32_t *bottom, uint32_t *top)
{
	uint32_t *p = bottom;

	while (p < top && *p == 0x5354434bu)
		p++;
	return (uint32_t)((uintptr_t)top - (uintptr_t)p);
}

uint32_t svc_stack_used(void)
{
	return stack_used(__svc_stack_bottom, __svc_stack_top);
}

uint32_t svc_stack_size(void)
{
	return (uint32_t)((uintptr_t)__svc_stack_top - (uintptr_t)__svc_stack_bottom);
}

static void print_irq_stats(uint32_t id)
{
	struct irq_stats st;
	uint32_t mean;

	irq_get_stats(id, &st);
	mean = st.lat_n ? (uint32_t)(st.lat_sum_ns / st.lat_n) : 0u;
	log_printf("stats irq=%u count=%u lat_min_ns=%u lat_mean_ns=%u lat_max_ns=%u nest_max=%u\n",
		   (unsigned)id, (unsigned)st.count, (unsigned)(st.lat_n ? st.lat_min_ns : 0u),
		   (unsigned)mean, (unsigned)st.lat_max_ns, (unsigned)st.nest_max);
}

static void print_stats(void)
{
	struct log_stats ls;
	uint32_t flags = irq_save();
	uint32_t c = cycles, pmin = period_min, pmax = period_max, ovr = overruns, mis = missed;

	irq_restore(flags);
	log_get_stats(&ls);
	log_printf("stats cycle=%u guest_us=%u period_min_ns=%u period_max_ns=%u overruns=%u missed=%u nest_max=%u "
		   "nest_test_ok=%u nest_test_fail=%u fpu_test_ok=%u fpu_test_fail=%u fpu_test_why=%u\n",
		   (unsigned)c, (unsigned)((timebase_now() - gt_start) / BOARD_TIMEBASE_TICKS_PER_US),
		   (unsigned)(c > 1u ? pmin : 0u), (unsigned)pmax, (unsigned)ovr, (unsigned)mis,
		   (unsigned)irq_nest_max(), (unsigned)nest_ok, (unsigned)nest_fail, (unsigned)fpu_ok,
		   (unsigned)fpu_fail, (unsigned)fpu_fail_why);
	print_irq_stats(BOARD_CYCLE_IRQ);
	print_irq_stats(BOARD_NEST_TEST_SGI);
	log_printf("stats link=%s attached=%d hb=%u spurious=%u unhandled=%u irq_disabled=%u "
		   "irq_disabled_last=%u trace_wraps=%u uart_dropped=%u svc_stack_used=%u\n",
		   link_backend(), link_attached(), (unsigned)link_heartbeat(),
		   (unsigned)irq_spurious(), (unsigned)irq_unhandled(), (unsigned)irq_disabled(),
		   (unsigned)irq_disabled_last(), (unsigned)ls.trace_wraps,
		   (unsigned)ls.uart_dropped,
		   (unsigned)svc_stack_used());
#if HAVE_AMP_LIB
	if (axis_can_count())
		axis_can_log_stats();
#endif
}

/*
 * The cooperative stop (the Zynq-7000's driver: STOP in the control word,
 * PRKD after parking) where the board has that contract. Linux's upstream
 * R5 driver has none: it powers the core down (FORCE_POWERDOWN) without
 * asking, so there the firmware never sees a stop (servod tells a stop
 * on request from a stall by remoteproc's state: docs/cycle.md).
 */
static int stop_requested(void)
{
#if BOARD_HAS_STOP_CONTRACT
	return mmio_read32(BOARD_STOP_CONTROL_ADDR) == ZSR_CTRL_STOP;
#else
	return 0;
#endif
}

#if BOARD_HAS_STOP_CONTRACT
__attribute__((noreturn)) void servo_quiesce_and_park(void)
{
	cpu_irq_disable();
	link_stopping();	/* before the heartbeat ends: not a stall */
	ttc_servo_stop();	/* Linux's cycle goes on (ttc.c) */
	idle_timer_stop();
#if HAVE_AMP_LIB
	if (axis_can_count())
		axis_can_stop();	/* the CAN controllers off the bus */
#endif
	irq_release_all();
	gic_cpu_disable();
	log_printf("stop: STOP seen after %u cycles; interrupts released, timer stopped; parking at %p\n",
		   (unsigned)cycles, (void *)(uintptr_t)BOARD_PARK_ADDR);
	log_flush();
	/* Caches cleaned and MMU off inside cpu_park (park.S), then PRKD. */
	cpu_park(BOARD_PARK_ADDR, BOARD_STOP_STATUS_ADDR, ZSR_STATUS_PARKED);
}
#else
__attribute__((noreturn)) void servo_quiesce_and_park(void)
{
	/* No stop contract: never asked to stop (stop_requested() is 0). */
	for (;;)
		wfi();
}
#endif

uint32_t start_irq_drained(void)
{
	return drain.n;
}

uint32_t start_irq_busy_prio(void)
{
	return drain.rpr_left;
}

/* An earlier run may have left interrupts active in this core's CPU
 * interface (an acknowledge never completed: a fault before the dispatcher
 * recorded it, a reset without a stop). Complete them, say so; if the
 * interface stays busy, say it loudly (here, and in SP_CMD_STATUS). */
static void drain_cpu_interface(void)
{
	char line[200];
	int len;

	gic_drain_own_active(&drain);
	if (drain.rpr_entry != 0xffu) {
		len = log_snprintf(line, sizeof(line), "gic: CPU interface busy at priority %02x on entry:",
				   (unsigned)drain.rpr_entry);
		for (uint32_t i = 0; i < drain.n && len > 0 && (uint32_t)len < sizeof(line); i++)
			len += log_snprintf(line + len, sizeof(line) - (uint32_t)len, "%s irq %u (prio %02x)",
					    i ? "," : " completed", (unsigned)drain.id[i],
					    (unsigned)drain.prio[i]);
		log_printf("%s%s; now %02x\n", line, drain.n ? "" : " nothing of this core's active",
			   (unsigned)drain.rpr_left);
	}
	if (drain.rpr_left != 0xffu)
		log_printf("error: gic: CPU interface still busy at priority %02x: no interrupt at or below it "
			   "is ever taken (the cycle interrupt is at %02x) until the GIC is reset\n",
			   (unsigned)drain.rpr_left, (unsigned)BOARD_CYCLE_PRIORITY);
	if (drain.still_active)
		log_printf("error: gic: %u interrupt(s) of this core still active (the last: irq %u), never "
			   "taken again until the GIC is reset\n",
			   (unsigned)drain.still_active, (unsigned)drain.still_last);
}

static void banner(void)
{
	log_printf("servoamp rpu_app %s (%s, built %s, gcc %s) board=%s variant=%s\n",
		   RPU_VERSION, RPU_GIT, RPU_BUILD_DATE, __VERSION__, BOARD_NAME, rpu_variant);
}

__attribute__((noreturn)) void servo_main(void)
{
	uint32_t gt_ps, last_stats = 0, slept_taken = 0, period_us;
	int uart_ok;

	cycles = 0;
	last_gt = 0;
	period_min = UINT32_MAX;
	period_max = overruns = missed = 0;
	period_changed = 0;
	sgi_stamp = sgi_seen = 0;
	nest_ok = nest_fail = 0;
	fpu_ok = fpu_fail = fpu_fail_why = 0;
	fpu_in = 1.7f;
	fpu_ref = fpu_bits(fpu_work(fpu_in));	/* outside any interrupt */

#if CONFIG_MMU
	memprot_init();
#endif
	log_init();
	uart_ok = uart_init() == 0;
	banner();	/* always the first line, on both sinks */
	if (!uart_ok)
		log_printf("uart: console UART clock gated in SLCR; logging to trace only\n");
#if BOARD_CPU_HAS_VBAR
	log_printf("cpu%u: mpidr=%08x vbar=%08x sctlr=%08x mmu=%s\n",
		   (unsigned)mpidr_cpu(), (unsigned)CP15_READ(0, c0, c0, 5),
		   (unsigned)CP15_READ(0, c12, c0, 0), (unsigned)CP15_READ(0, c1, c0, 0),
		   memprot_enabled() ? memprot_describe() : "off");
#else
	log_printf("cpu%u: mpidr=%08x sctlr=%08x (no VBAR: vectors at 0x0) mpu=%s\n",
		   (unsigned)mpidr_cpu(), (unsigned)CP15_READ(0, c0, c0, 5), (unsigned)CP15_READ(0, c1, c0, 0),
		   memprot_enabled() ? memprot_describe() : "off");
#endif
	log_printf("memory: image %p..%p carveout %08x+%08x trace %p+%u amp %08x+%08x\n",
		   (void *)BOARD_IMAGE_BASE, (void *)__image_end, (unsigned)BOARD_CARVEOUT_BASE,
		   (unsigned)BOARD_CARVEOUT_SIZE, (void *)trace_buf, (unsigned)BOARD_TRACE_SIZE,
		   (unsigned)BOARD_AMP_BASE, (unsigned)BOARD_AMP_SIZE);
	if (mpidr_cpu() != BOARD_CPU_ID)
		log_printf("warning: running on cpu%u, devicetree says cpu%u\n",
			   (unsigned)mpidr_cpu(), (unsigned)BOARD_CPU_ID);
	if (timebase_init(&gt_ps))
		log_printf("warning: time base stopped (its owner starts it): tick-based figures are wrong\n");
	else if (gt_ps)
		log_printf("timebase: prescaler %u set by its owner; ticks scaled by %u to %u MHz units\n",
			   (unsigned)gt_ps, (unsigned)(gt_ps + 1u), (unsigned)BOARD_TIMEBASE_TICKS_PER_US);
	log_flush();

	irq_init();
#if BOARD_GIC_OWNED
	gic_dist_enable();	/* this core's own GIC (the RPU's): enabled here */
#endif
	if (!gic_dist_enabled())
		log_printf("warning: GIC distributor disabled (owned by Linux, not enabled here); "
			   "no interrupt until it is\n");
	drain_cpu_interface();
	gic_cpu_init(GIC_PMR, GIC_BPR);

	if (irq_register(BOARD_CYCLE_IRQ, cycle_handler, ttc_cycle_clear,
			 BOARD_CYCLE_IRQ_LEVEL ? IRQ_TRIGGER_LEVEL : IRQ_TRIGGER_EDGE, 0) ||
	    irq_set_priority(BOARD_CYCLE_IRQ, BOARD_CYCLE_PRIORITY) ||
	    irq_set_latency_probe(BOARD_CYCLE_IRQ, ttc_cycle_since_fire_ns) ||
	    irq_register(BOARD_NEST_TEST_SGI, nest_test_handler, 0, IRQ_TRIGGER_EDGE, 0) ||
	    irq_set_priority(BOARD_NEST_TEST_SGI, BOARD_NEST_TEST_PRIORITY) ||
	    irq_set_latency_probe(BOARD_NEST_TEST_SGI, nest_test_latency))
		log_printf("error: interrupt registration failed\n");

	link_init();
	gt_start = timebase_now();
	/* A restart finds the cycle timer running (ttc.c): its period stands
	 * until Linux sets cycle_period_us again, and Linux loses no cycle. */
	period_us = ttc_running_period_us();
	if (period_us)
		log_printf("cycle: the cycle timer runs at %u us (a restart): period kept, Linux's counter untouched\n",
			   (unsigned)period_us);
	else
		period_us = BOARD_CYCLE_PERIOD_US;
	if (ttc_cycle_start(period_us))
		log_printf("error: cycle period %u us not reachable\n", (unsigned)period_us);
#if HAVE_AMP_LIB
	else
		app_param_running(SP_P_cycle_period_us, period_us);
#endif
	last_period_ns = ttc_period_ns();
	irq_enable(BOARD_NEST_TEST_SGI);
	irq_enable(BOARD_CYCLE_IRQ);
	if (idle_timer_start())
		log_printf("error: idle wake (the platform's idle_timer.c) not registered: STOP is seen only while "
			   "cycle interrupts come\n");
	cpu_irq_enable();

	log_printf("cycle: irq %u (%s) prio %02x, ttc %08x counter %u, period %u us "
		   "(interval %u, prescaler %s/%u); nest test: sgi %u prio %02x\n",
		   (unsigned)BOARD_CYCLE_IRQ, BOARD_CYCLE_IRQ_LEVEL ? "level" : "edge",
		   (unsigned)BOARD_CYCLE_PRIORITY, (unsigned)BOARD_TTC_BASE,
		   (unsigned)BOARD_CYCLE_COUNTER, (unsigned)BOARD_CYCLE_PERIOD_US,
		   (unsigned)BOARD_CYCLE_INTERVAL, BOARD_CYCLE_PS_EN ? "on" : "off",
		   (unsigned)(BOARD_CYCLE_PS_EN ? 2u << BOARD_CYCLE_PS_V : 1u),
		   (unsigned)BOARD_NEST_TEST_SGI, (unsigned)BOARD_NEST_TEST_PRIORITY);

#if BOARD_HAS_STOP_CONTRACT
	mmio_write32(BOARD_STOP_STATUS_ADDR, ZSR_STATUS_RUNNING);
	dsb();
	log_printf("running: status %p = RUN!, polling stop word %p\n",
		   (void *)(uintptr_t)BOARD_STOP_STATUS_ADDR, (void *)(uintptr_t)BOARD_STOP_CONTROL_ADDR);
#else
	log_printf("running: no stop word (the remoteproc driver powers this core down to stop it)\n");
#endif

	for (;;) {
		uint32_t c;

		if (stop_requested())
			servo_quiesce_and_park();
		log_poll();
		c = cycles;
		{
			uint32_t flags = irq_save();
			struct link_stats ls = { cycles, missed, overruns };

			irq_restore(flags);
			link_poll(c, &ls);
			if (ttc_period_ns() != last_period_ns) {
				/* cycle_period_us changed: the next gap is not a period */
				last_period_ns = ttc_period_ns();
				period_changed = 1;
				period_min = UINT32_MAX;
				period_max = 0;
			}
		}
		if (c - last_stats >= BOARD_STATS_CYCLES) {
			last_stats = c;
			print_stats();
			if (timebase_changed())
				log_printf("warning: time base prescaler changed by its owner\n");
		}
		/* Sleep until the next interrupt while the distributor is
		 * enabled by its owner: the cycle interrupt, or at the latest
		 * the idle wake (idle_timer.h), so STOP is seen even when
		 * cycle interrupts stop. Only while interrupts keep arriving
		 * (one of ours was handled since the last sleep); else the
		 * loop polls. Any interrupt counts, not only the cycle and the
		 * idle wake: a wake by another source (a CAN controller's RX,
		 * every cycle on the fieldbus) used to leave the loop polling
		 * until the next cycle interrupt, most of every cycle, and
		 * under -icount a polling CPU1 takes every other turn from
		 * CPU0 (Linux), which then woke servod up to 500 us late. */
		if (CONFIG_IDLE_WFI && gic_dist_enabled() && irq_taken() != slept_taken) {
			slept_taken = irq_taken();
			wfi();
		}
	}
}
