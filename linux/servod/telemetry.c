// SPDX-License-Identifier: MIT
/*
 * telemetry.c - servod's use of the telemetry transport (linux/telemetry,
 * docs/telemetry.md): its option, its start and stop, the cycle record
 * (cycle thread: lock-free ring, no syscall, never waits) and the events
 * of an attach (GAP and the parameter set loaded).
 */
#define _GNU_SOURCE
#include <errno.h>
#include <stdlib.h>
#include <string.h>

#include "context.h"

/* "ADDR:PORT", "[V6ADDR]:PORT" or "off" -> telem_addr / telem_port; 0 ok. */
int telemetry_parse_opt(struct servod_opts *o)
{
	const char *s = o->telem, *colon;
	char *end;
	unsigned long port;
	size_t alen;

	if (!strcmp(s, "off"))
		return 0;
	colon = strrchr(s, ':');
	if (!colon || colon == s)
		return -1;
	port = strtoul(colon + 1, &end, 10);
	if (!colon[1] || *end || port > 65535)
		return -1;
	if (s[0] == '[') {
		if (colon[-1] != ']')
			return -1;
		s++;
		alen = (size_t)(colon - 1 - s);
	} else {
		alen = (size_t)(colon - s);
	}
	if (!alen || alen >= sizeof(o->telem_addr))
		return -1;
	memcpy(o->telem_addr, s, alen);
	o->telem_addr[alen] = 0;
	o->telem_port = (uint16_t)port;
	return 0;
}

void telemetry_start(struct servod *sd)
{
	struct telem_cfg tc;
	int rc;

	if (!strcmp(sd->opt.telem, "off")) {
		logm(sd, "telemetry off");
		return;
	}
	telem_cfg_defaults(&tc);
	tc.listen_addr = sd->opt.telem_addr;
	tc.port = sd->opt.telem_port;
	tc.controller_id = sd->opt.id;
	tc.n_axes = sd->axes;
	tc.cycle_period_ns = sd->period_ns;
	tc.clock_hz = sd->opt.servo_clock_hz;
	tc.drain_interval_us = 10000u;	/* 100 wake-ups/s; the ring holds 4,096 cycles */
	tc.mlock = 1;
	tc.app_counters = cycle_stats_counters;
	tc.app_arg = &sd->pub;
	rc = telem_init(&sd->telem, &tc);
	if (rc == 0)
		rc = telem_start(&sd->telem);
	if (rc) {
		logw(sd, "telemetry off: %s:%u: %s", sd->opt.telem_addr, sd->opt.telem_port, strerror(-rc));
		telem_destroy(&sd->telem);
		return;
	}
	sd->telem_on = 1;
	logm(sd, "telemetry on %s:%u (%u axes, ring %u cycles)", sd->opt.telem_addr, telem_port(&sd->telem),
	     tc.n_axes, tc.ring_capacity);
}

void telemetry_cycle(struct servod *sd, const struct cycle_wake *w, int rc, const struct amp_rx_info *rx,
		     const struct amp_cmd_axis *cmd, uint32_t n)
{
	const struct amp_fb_record *fb = &sd->amp.fb;
	uint32_t nfb = fb->n_axes < n ? fb->n_axes : n;	/* the axes the feedback covers */
	struct telem_cycle tr;

	if (!sd->telem_on)
		return;
	tr.cycle = sd->stats.cycles;
	tr.t_ns = w->t_ns;
	tr.servo_cycle = fb->cycle;
	tr.t_cycle = fb->t_cycle;
	tr.irq_latency = fb->irq_latency;
	tr.wake_latency_ns = w->lat_ns;
	/* AMP_RX_* and TELEM_X_* have the same values */
	tr.exchange = (rc == AMP_OK || rc == AMP_E_PEER_ERROR) ? rx->status : TELEM_X_NONE;
	tr.missed = rx->missed;
	tr.servo_status = fb->status;
	tr.result = rc;
	tr.n_axes = n;
	memcpy(tr.cmd, cmd, n * sizeof(cmd[0]));
	memcpy(tr.fb, fb->axis, nfb * sizeof(tr.fb[0]));
	memset(tr.fb + nfb, 0, (n - nfb) * sizeof(tr.fb[0]));
	telem_push_cycle(&sd->telem, &tr);
}

void telemetry_attach(struct servod *sd, int recovery, uint64_t stall_cycle, uint64_t cycle)
{
	if (!sd->telem_on)
		return;
	/* the attach as a GAP event (nothing lost: the cycles in between are
	 * on record with their exchange status): a recovery spans stall
	 * detection .. now */
	if (recovery)
		telem_push_gap(&sd->telem, 0, stall_cycle && stall_cycle <= cycle ? stall_cycle : cycle, cycle, 0,
			       TELEM_GAP_RECOVERY);
	else
		telem_push_gap(&sd->telem, 0, cycle, cycle, 0, TELEM_GAP_CONTROLLER_RESTART);
	/* the set just loaded into the servo */
	for (int i = 0; i < SP_P_COUNT; i++)
		if (param_desc[i].flags & SP_F_RESTORE)
			params_publish(sd, (uint32_t)i, sd->pset[i]);
}

void telemetry_stop(struct servod *sd)
{
	if (!sd->telem_on)
		return;
	/* after the cycle thread: drains the ring, final STATS, closes */
	telem_stop(&sd->telem);
	sd->telem_on = 0;
	telem_destroy(&sd->telem);
}
