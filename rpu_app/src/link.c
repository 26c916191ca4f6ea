/* SPDX-License-Identifier: MIT */
/*
 * link.c - the firmware's side of the exchange with Linux, through amp_lib
 * (amp/amp.h) and the application protocol (servoamp/servo_proto.h).
 *
 * Cycle interrupt (link_cycle, the servo's steps of the periodic exchange; the dispatcher
 * clears the interrupt flag after the handler):
 *   1. heartbeat, Linux's state and epoch, watchdog   amp_servo_cycle_rx()
 *   2. poll the semaphore, at most RX_TIMEOUT_US
 *   3. read the commands (switch buffer)
 *   -- fine interpolation, loops and plants            app_cycle()
 *   4. write the feedback (switch buffer)              amp_servo_cycle_tx()
 *   5. semaphore back to idle
 * AMP_E_STALLED (Linux heartbeat still for wd_limit cycles) or
 * AMP_E_PEER_ABSENT (Linux closed / re-initialised the region): every axis
 * is brought to a controlled stop and the servo line says SAFESTOP with
 * the reason; it stays so until SP_CMD_RESUME. A region closed or made
 * anew before Linux's first command in the attach is attached again,
 * without a safe stop: nothing was commanded to stop.
 *
 * Background loop (link_poll): attach / re-attach (retried every
 * BOARD_ATTACH_RETRY_CYCLES cycles), and the parameter service polled from
 * the mailbox (never blocking, never inside the cycle).
 */
#include <stdint.h>

#ifndef HAVE_AMP_LIB
#define HAVE_AMP_LIB 0
#endif

#if !HAVE_AMP_LIB
/* AMP_LIB=0: no transport, no application; a local heartbeat only. */
#include "link.h"
#include "log.h"

static volatile uint32_t local_hb;
volatile struct link_diag link_diag;
volatile struct link_debug link_debug;

void link_init(void)
{
	local_hb = 0;
	link_debug = (struct link_debug){ 0 };
	log_printf("link: amp_lib servo side not linked; heartbeat kept locally\n");
}

void link_poll(uint32_t cycle, const struct link_stats *ls)
{
	(void)cycle;
	(void)ls;
}

void link_cycle(uint32_t t_entry, uint32_t lat_ns)
{
	(void)t_entry;
	(void)lat_ns;
	local_hb++;
}

int link_attached(void)
{
	return 0;
}

void link_stopping(void)
{
}

uint32_t link_heartbeat(void)
{
	return local_hb;
}

const char *link_backend(void)
{
	return "local";
}

#else /* HAVE_AMP_LIB */

#include "board.h"	/* AMP_BOARD_TICKS_PER_US for amp_lib's port: first */
#include "amp/amp.h"
#include "app.h"
#include "arch.h"
#include "gic.h"
#include "timebase.h"
#include "irq.h"
#include "link.h"
#include "log.h"
#include "memprot.h"
#include "servo.h"
#include "servoamp/servo_proto.h"
#include "ttc.h"

#define RX_TIMEOUT_US 20u

static struct amp_servo amp;
static volatile int attached;
/* Linux's first command in this attach taken; attaches ended before one
 * (the region closed or made anew under it), and how many were logged */
static volatile uint32_t commanded, uncommanded_ends;
static uint32_t uncommanded_logged;
static volatile uint32_t local_hb, hang, crash_req, linux_cycle, bad_answer, fault_req, stack_req;
static uint32_t next_try, stack_pending, irq_abort_pending;
static int last_err;
static struct amp_fb_axis fb[AMP_MAX_AXES];

/*
 * Costs (global-timer ticks), written by the cycle handler. They describe
 * the configuration in force: a change of the axis count or of the cycle
 * period starts them again (param_applied), so that one boot can measure
 * the cost of each configuration (bench/cycle/cycle_bench.py sweeps 1..8
 * axes at several rates). worst_ticks is never restarted: it is the worst
 * handler cost since the start, which check_load holds a new period to.
 */
static struct {
	uint32_t n;
	uint32_t rx_max, ctrl_max, tx_max, cyc_max;
	uint64_t rx_sum, ctrl_sum, tx_sum, cyc_sum;
	uint32_t lat_max_ns;
} cost;
static uint32_t worst_ticks;

static uint32_t period_refused;	/* cycle_period_us values refused (check_load) */

/* Diagnostics read by the tests through the QEMU monitor (symbol). */
volatile struct link_diag link_diag;
volatile struct link_debug link_debug;

void link_init(void)
{
	attached = 0;
	commanded = uncommanded_ends = uncommanded_logged = 0;
	local_hb = hang = crash_req = linux_cycle = bad_answer = fault_req = stack_req = 0;
	stack_pending = irq_abort_pending = 0;
	next_try = 0;
	last_err = 1;	/* nothing reported yet */
	amp = (struct amp_servo){ 0 };
	cost = (__typeof__(cost)){ 0 };
	worst_ticks = 0;
	link_diag = (struct link_diag){ 0 };
	link_debug = (struct link_debug){ 0 };
	period_refused = 0;
	app_init();
}

static void enter_safestop(uint32_t reason, int write_line)
{
	if (!app_in_safestop()) {
		app_safestop(reason);
		link_diag.safestop_cycle = amp.cycle;
		link_diag.safestop_reason = reason;
		link_diag.last_linux_beat_cycle = amp.cycle - amp.wd.still;
	}
	if (write_line)
		amp_servo_set_state(&amp, AMP_SSTATE_SAFESTOP, app_fault());
}

/*
 * Debug (SP_DEBUG_STACK): recurse until the SVC stack overflows. Each frame
 * is 256 bytes of locals (well below the 4 KiB guard page, so the guard is
 * always touched, never stepped over) and passes their address to the
 * callee, so the frame must live across the call: no tail call, no loop.
 * The depth is bounded (twice the stack) in case no guard stops it.
 */
static __attribute__((noinline, noclone)) uint32_t stack_eat(volatile uint32_t *up, uint32_t depth)
{
	volatile uint32_t pad[64];

	pad[0] = up ? up[0] + 1u : 0u;
	pad[63] = depth;
	if (!depth)
		return pad[0];
	return stack_eat(pad, depth - 1u) + pad[63];
}

void link_cycle(uint32_t t_entry, uint32_t lat_ns)
{
	struct amp_rx_info rx;
	uint32_t t1, t2, t3, n, was_ss;
	int rc;

	if (stack_req) {
		stack_req = 0;
		(void)stack_eat(0, 2u * svc_stack_size() / (64u * 4u));
	}
	if (hang)
		return;	/* debug: stuck in the cycle, no heartbeat, no exchange */
	local_hb++;
	if (!attached) {
		(void)app_cycle(0, 0, fb);	/* plants keep running, axes disabled */
		return;
	}
	was_ss = (uint32_t)app_in_safestop();
	rc = amp_servo_cycle_rx(&amp, RX_TIMEOUT_US * AMP_BOARD_TICKS_PER_US, &rx);
	t1 = timebase_now32();
	if (rc == AMP_E_STALLED) {
		enter_safestop(SP_FAULT_LINUX_STALL, 1);
	} else if (rc == AMP_E_PEER_ABSENT) {
		/* Linux closed the region (same epoch): say why in the servo
		 * line; re-initialised (new epoch): the line is Linux's again.
		 * Before Linux's first command in this attach there is nothing
		 * to stop (the axes are as the boot or an earlier safe stop
		 * left them): the attach met Linux closing the region or making
		 * a new one (servod after a stop: docs/cycle.md, "A stop and a
		 * start in quick succession"), and is simply made again. */
		if (commanded)
			enter_safestop(SP_FAULT_LINUX_GONE,
				       mmio_read32((uintptr_t)&amp.ocm->hdr.epoch) == amp.epoch);
		else
			uncommanded_ends++;
		attached = 0;
		(void)app_cycle(0, 0, fb);
		return;
	}
	if (rx.status == AMP_RX_FRESH || rx.status == AMP_RX_MISSED) {
		linux_cycle = amp.cmd.cycle;
		commanded = 1;
	}
	n = app_cycle(&amp.cmd, rx.status == AMP_RX_FRESH || rx.status == AMP_RX_MISSED, fb);
	if (was_ss && !app_in_safestop())
		amp_servo_set_state(&amp, AMP_SSTATE_RUNNING, 0);	/* resumed */
	if (!was_ss && app_in_safestop())
		amp_servo_set_state(&amp, AMP_SSTATE_SAFESTOP, app_fault());
	if (app_in_safestop() && !link_diag.standstill_cycle && app_stop_cycles())
		link_diag.standstill_cycle = link_diag.safestop_cycle + app_stop_cycles() - 1u;
	if (link_debug.slow_us) {	/* debug: a slow control law */
		uint32_t w = link_debug.slow_us * BOARD_TIMEBASE_TICKS_PER_US;

		while (timebase_now32() - t1 < w)
			compiler_barrier();
	}
	t2 = timebase_now32();
	(void)amp_servo_cycle_tx(&amp, fb, n, t_entry, lat_ns / (1000u / AMP_BOARD_TICKS_PER_US));
	t3 = timebase_now32();

	cost.n++;
	t3 -= t_entry;
	t2 -= t1;
	t1 -= t_entry;
	cost.rx_sum += t1;
	cost.ctrl_sum += t2;
	cost.tx_sum += t3 - t1 - t2;
	cost.cyc_sum += t3;
	if (t1 > cost.rx_max)
		cost.rx_max = t1;
	if (t2 > cost.ctrl_max)
		cost.ctrl_max = t2;
	if (t3 - t1 - t2 > cost.tx_max)
		cost.tx_max = t3 - t1 - t2;
	if (t3 > cost.cyc_max)
		cost.cyc_max = t3;
	if (t3 > worst_ticks)
		worst_ticks = t3;
	if (lat_ns > cost.lat_max_ns && lat_ns != 0xffffffffu)
		cost.lat_max_ns = lat_ns;
}

/* Word i of a request payload: amp_lib's private copy of the request,
 * already validated (never OCM, which Linux may rewrite at any time). */
static uint32_t rd_word(const uint8_t *p, uint32_t i)
{
	p += 4u * i;
	return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

static uint32_t mean(uint64_t sum, uint32_t n)
{
	return n ? (uint32_t)(sum / n) : 0u;
}

/*
 * A parameter value the cycle can sustain: a new cycle_period_us must hold
 * the worst handler cost measured so far with its margin (sp_period_fits);
 * the period in force is always accepted again. SP_OK or SP_E_OVERLOAD.
 */
static int32_t check_load(uint32_t id, uint32_t v)
{
	uint32_t worst_ns = worst_ticks * (1000u / AMP_BOARD_TICKS_PER_US);

	if (id != SP_P_cycle_period_us || v == app_param(id) || sp_period_fits(v, worst_ns))
		return SP_OK;
	period_refused++;
	log_printf("param: cycle_period_us %u refused: worst handler cost %u ns measured, %u/%u of it needed\n",
		   (unsigned)v, (unsigned)worst_ns, (unsigned)SP_PERIOD_MARGIN_NUM,
		   (unsigned)SP_PERIOD_MARGIN_DEN);
	return SP_E_OVERLOAD;
}

/*
 * A parameter applied (app_param_apply); a new axis count or cycle period
 * starts the cost figures again (the cycle handler updates them: masked).
 */
static void param_applied(uint32_t id, uint32_t old)
{
	uint32_t flags;

	if (id == SP_P_wd_limit)
		amp.wd.limit = app_param(id);
	if ((id != SP_P_axes && id != SP_P_cycle_period_us) || app_param(id) == old)
		return;
	flags = irq_save();
	cost = (__typeof__(cost)){ 0 };
	irq_restore(flags);
}

/* Serve one request; returns the status, fills out/len. */
static int32_t serve(const struct amp_mbox_req *req, uint32_t *out, uint32_t *len,
		     const struct link_stats *ls)
{
	uint32_t nw = req->length / 4u;

	*len = 0;
	if (req->length % 4u)
		return SP_E_LENGTH;
	switch (req->command) {
	case SP_CMD_PARAM_GET: {
		uint32_t id;

		if (nw != 1u)
			return SP_E_LENGTH;
		id = rd_word(req->payload, 0);
		if (id >= SP_P_COUNT)
			return SP_E_ID;
		out[0] = id;
		out[1] = app_param(id);
		if (bad_answer) {	/* debug: an answer servod must refuse */
			bad_answer = 0;
			out[1] = 0xffffffffu;
		}
		*len = 8;
		return SP_OK;
	}
	case SP_CMD_PARAM_SET: {
		uint32_t id, v, old;
		int32_t rc;

		if (nw != 2u)
			return SP_E_LENGTH;
		id = rd_word(req->payload, 0);
		v = rd_word(req->payload, 1);
		rc = app_param_check(id, v);
		if (rc == SP_OK)
			rc = check_load(id, v);
		if (rc != SP_OK)
			return rc;
		old = app_param(id);
		app_param_apply(id, v);
		param_applied(id, old);
		out[0] = id;
		out[1] = app_param(id);
		if (bad_answer) {	/* debug: an answer servod must refuse */
			bad_answer = 0;
			out[1] = 0xffffffffu;
		}
		*len = 8;
		return SP_OK;
	}
	case SP_CMD_PARAM_SET_MANY: {
		uint32_t cnt, ids[SP_SET_MANY_MAX], vals[SP_SET_MANY_MAX];

		if (nw < 1u)
			return SP_E_LENGTH;
		cnt = rd_word(req->payload, 0);
		if (cnt > SP_SET_MANY_MAX || nw != 1u + 2u * cnt)
			return SP_E_LENGTH;
		/* each pair read once; checked, then applied, from this copy */
		for (uint32_t i = 0; i < cnt; i++) {
			ids[i] = rd_word(req->payload, 1u + 2u * i);
			vals[i] = rd_word(req->payload, 2u + 2u * i);
		}
		for (uint32_t i = 0; i < cnt; i++) {
			int32_t rc = app_param_check(ids[i], vals[i]);

			if (rc == SP_OK)
				rc = check_load(ids[i], vals[i]);
			if (rc != SP_OK)
				return rc;
		}
		for (uint32_t i = 0; i < cnt; i++) {
			uint32_t old = app_param(ids[i]);

			app_param_apply(ids[i], vals[i]);
			param_applied(ids[i], old);
		}
		out[0] = cnt;
		*len = 4;
		return SP_OK;
	}
	case SP_CMD_STATUS: {
		struct sp_status s = { 0 };
		uint32_t flags;

		if (nw)
			return SP_E_LENGTH;
		s.version = SP_VERSION;
		s.state = mmio_read32((uintptr_t)&amp.ocm->servo_line.state);
		s.fault = app_fault();
		s.cycles = ls->cycles;
		s.missed = ls->missed;
		s.overruns = ls->overruns;
		flags = irq_save();
		s.rx_fresh = amp.st.fresh;
		s.rx_stale = amp.st.stale;
		s.rx_torn = amp.st.torn;
		s.rx_missed = amp.st.missed;
		s.rx_invalid = amp.st.invalid;
		s.samples = cost.n;
		s.rx_ticks_max = cost.rx_max;
		s.rx_ticks_mean = mean(cost.rx_sum, cost.n);
		s.ctrl_ticks_max = cost.ctrl_max;
		s.ctrl_ticks_mean = mean(cost.ctrl_sum, cost.n);
		s.tx_ticks_max = cost.tx_max;
		s.tx_ticks_mean = mean(cost.tx_sum, cost.n);
		s.cycle_ticks_max = cost.cyc_max;
		s.cycle_ticks_mean = mean(cost.cyc_sum, cost.n);
		s.irq_lat_max_ns = cost.lat_max_ns;
		s.linux_cycle = linux_cycle;
		s.hb_linux_cycles = amp.wd.still;
		irq_restore(flags);
		s.attach_count = mmio_read32((uintptr_t)&amp.ocm->servo_line.attach_count);
		s.period_us = app_param(SP_P_cycle_period_us);
		s.axes = app_param(SP_P_axes);
		s.safestops = app_safestops();
		s.stop_cycles = app_stop_cycles();
		s.mbox_served = amp.st.mbox_ok;
		s.svc_stack_used = svc_stack_used();
		s.svc_stack_size = svc_stack_size();
		s.irq_unhandled = irq_unhandled();
		s.irq_disabled = irq_disabled();
		s.irq_disabled_last = irq_disabled_last();
		s.period_refused = period_refused;
		s.irq_drained = start_irq_drained();
		s.irq_busy_prio = start_irq_busy_prio();
		for (uint32_t i = 0; i < sizeof(s) / 4u; i++)
			out[i] = ((uint32_t *)&s)[i];
		*len = sizeof(s);
		return SP_OK;
	}
	case SP_CMD_RESUME:
		if (nw)
			return SP_E_LENGTH;
		if (!app_resume_allowed())
			return SP_E_STATE;
		app_resume();
		return SP_OK;
	case SP_CMD_DEBUG: {
		uint32_t what;

		if (nw < 1u)
			return SP_E_LENGTH;
		what = rd_word(req->payload, 0);
		if (nw != (what == SP_DEBUG_SLOW ? 2u : 1u))
			return SP_E_LENGTH;
		if (what == SP_DEBUG_SLOW) {
			uint32_t us = rd_word(req->payload, 1);

			if (us > 10000u)
				return SP_E_RANGE;
			log_printf("debug: every cycle handler now takes %u us longer\n", (unsigned)us);
			link_debug.slow_us = us;
		} else if (what == SP_DEBUG_OVERLOAD) {
			log_printf("debug: overload requested: every cycle handler ends with its interrupt pending again\n");
			link_debug.overload = 1;
		} else if (what == SP_DEBUG_STRAY_IRQ) {
			link_debug.stray_req = 1;	/* started by link_poll, after the answer */
		} else if (what == SP_DEBUG_HANG) {
			log_printf("debug: hang requested: cycle work and heartbeat stop, STOP still honoured\n");
			hang = 1;
		} else if (what == SP_DEBUG_CRASH) {
			log_printf("debug: crash requested: undefined instruction in the background loop\n");
			crash_req = 1;
		} else if (what == SP_DEBUG_FAULT) {
			log_printf("debug: fault requested: servo line FAULT, then cycle work and heartbeat stop\n");
			fault_req = 1;	/* after the answer (link_poll) */
		} else if (what == SP_DEBUG_STACK) {
			if (!memprot_enabled())
				return SP_E_STATE;	/* no guard page: it would be silent */
			log_printf("debug: SVC stack overflow requested: the next cycle handler recurses into the guard page\n");
			stack_pending = 1;	/* armed after the answer (link_poll) */
		} else if (what == SP_DEBUG_IRQ_ABORT) {
			if (!memprot_enabled())
				return SP_E_STATE;	/* no guard page to fault on */
			log_printf("debug: abort requested: the next cycle interrupt faults right after its acknowledge\n");
			irq_abort_pending = 1;	/* armed after the answer (link_poll) */
		} else if (what == SP_DEBUG_BADPARAM) {
			log_printf("debug: the next parameter answer carries an out-of-range value\n");
			bad_answer = 1;
		} else {
			return SP_E_RANGE;
		}
		return SP_OK;
	}
	default:
		return SP_E_CMD;
	}
}

void link_poll(uint32_t cycle, const struct link_stats *ls)
{
	struct amp_mbox_req req;
	uint32_t out[(sizeof(struct sp_status) + 3u) / 4u + 2u];
	uint32_t len;
	int rc;

	if (crash_req) {
		crash_req = 0;
		__asm__ volatile(".inst 0xe7f000f0" ::: "memory");	/* udf #0 */
	}
	if (link_debug.stray_req == 1u) {
		uint32_t id = ttc_stray_start();

		log_printf("debug: stray interrupt %u (no handler here): level, this core, never cleared\n",
			   (unsigned)id);
		gic_irq_config(id, 0xc0u, 1);
		gic_irq_enable(id);
		link_debug.stray_req = 2;	/* started */
	}
	if (hang)
		return;
	if (attached) {
		rc = amp_servo_mbox_poll(&amp, &req);
		if (rc == 1) {
			int32_t st = serve(&req, out, &len, ls);

			(void)amp_servo_mbox_respond(&amp, st, out, len);
		}
		if (stack_pending) {
			stack_pending = 0;
			stack_req = 1;	/* the next cycle handler overflows */
		}
		if (irq_abort_pending) {
			irq_abort_pending = 0;
			(void)irq_debug_abort_next(BOARD_CYCLE_IRQ);
		}
		if (fault_req) {
			fault_req = 0;
			hang = 1;	/* first: the cycle handler no longer writes the line */
			compiler_barrier();
			amp_servo_set_state(&amp, AMP_SSTATE_FAULT, SP_FAULT_DEBUG);
		}
		return;
	}
	if (uncommanded_ends != uncommanded_logged) {
		uncommanded_logged = uncommanded_ends;
		log_printf("link: the region was closed or made anew before Linux's first command in this attach "
			   "(%u times): attaching again, no safe stop\n", (unsigned)uncommanded_logged);
	}
	if ((int32_t)(cycle - next_try) < 0)
		return;
	next_try = cycle + BOARD_ATTACH_RETRY_CYCLES;
	rc = amp_servo_attach(&amp, (void *)(uintptr_t)BOARD_AMP_BASE, BOARD_AMP_SIZE);
	if (rc == AMP_OK) {
		uint32_t wd = app_param(SP_P_wd_limit);

		/* Linux's header gives the watchdog limit until servod loads
		 * the parameter set. */
		if (wd != amp.wd.limit)
			app_param_apply(SP_P_wd_limit, amp.wd.limit);
		if (app_in_safestop())
			amp_servo_set_state(&amp, AMP_SSTATE_SAFESTOP, app_fault());
		commanded = 0;
		compiler_barrier();
		attached = 1;
		log_printf("link: attached to amp_lib region %p epoch %u attach_count %u (cycle %u)\n",
			   (void *)(uintptr_t)BOARD_AMP_BASE, (unsigned)amp.epoch,
			   (unsigned)mmio_read32((uintptr_t)&amp.ocm->servo_line.attach_count),
			   (unsigned)cycle);
	} else if (rc != last_err) {
		log_printf("link: amp_servo_attach: %s (%d); retry every %u cycles\n",
			   amp_strerror(rc), rc, (unsigned)BOARD_ATTACH_RETRY_CYCLES);
	}
	last_err = rc;
}

int link_attached(void)
{
	return attached;
}

void link_stopping(void)
{
	if (attached)
		amp_servo_set_state(&amp, AMP_SSTATE_STOPPING, 0);
}

uint32_t link_heartbeat(void)
{
	return local_hb;
}

const char *link_backend(void)
{
	return "amp_lib";
}

#endif /* HAVE_AMP_LIB */
