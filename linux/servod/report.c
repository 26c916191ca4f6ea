// SPDX-License-Identifier: MIT
/* report.c - the "status" and "stats" requests: what `ampctl status` and
 * `ampctl stats` print (key=value lines; tests and tools read them). */
#define _GNU_SOURCE
#include <stdio.h>
#include <string.h>

#include "context.h"

static const char *sstate_name(uint32_t s)
{
	switch (s) {
	case AMP_SSTATE_OFFLINE: return "OFFLINE";
	case AMP_SSTATE_RUNNING: return "RUNNING";
	case AMP_SSTATE_SAFESTOP: return "SAFESTOP";
	case AMP_SSTATE_FAULT: return "FAULT";
	case AMP_SSTATE_STOPPING: return "STOPPING";
	default: return "?";
	}
}

static const char *fault_name(uint32_t f)
{
	switch (f) {
	case SP_FAULT_NONE: return "none";
	case SP_FAULT_LINUX_STALL: return "linux-stalled";
	case SP_FAULT_LINUX_GONE: return "linux-gone";
	case SP_FAULT_FOLLOWING: return "following-error";
	default: return "other";
	}
}

/* SP_AX_DRIVE() of a status word, as `ampctl status` prints it */
static const char *drive_name(uint32_t d)
{
	static const char *const names[SP_DRIVE_STATES] = {
		[SP_DRIVE_INTERNAL] = "internal",
		[SP_DRIVE_OFFLINE] = "offline",
		[SP_DRIVE_CONFIGURING] = "configuring",
		[SP_DRIVE_NOT_READY] = "not-ready-to-switch-on",
		[SP_DRIVE_SWITCH_ON_DISABLED] = "switch-on-disabled",
		[SP_DRIVE_READY] = "ready-to-switch-on",
		[SP_DRIVE_SWITCHED_ON] = "switched-on",
		[SP_DRIVE_OPERATION_ENABLED] = "operation-enabled",
		[SP_DRIVE_QUICK_STOP] = "quick-stop-active",
		[SP_DRIVE_FAULT_REACTION] = "fault-reaction-active",
		[SP_DRIVE_FAULT] = "fault",
	};

	return d < SP_DRIVE_STATES ? names[d] : "?";
}

/* SP_AX_NMT() of a status word */
static const char *nmt_name(uint32_t v)
{
	static const char *const names[SP_NMT_STATES] = {
		[SP_NMT_NONE] = "-",
		[SP_NMT_BOOTUP] = "boot-up",
		[SP_NMT_STOPPED] = "stopped",
		[SP_NMT_OPERATIONAL] = "operational",
		[SP_NMT_PRE_OPERATIONAL] = "pre-operational",
	};

	return v < SP_NMT_STATES ? names[v] : "?";
}

/* What an axis's error code means when the CANopen master raised it
 * itself (rpu_app/src/canopen_master.h CO_ERR_*); NULL for the drive's
 * own EMCY codes (CiA 402: look them up in the drive's manual). */
static const char *master_error(uint32_t code)
{
	switch (code) {
	case 0x8130: return "heartbeat lost";
	case 0x8140: return "bus off, controller restarted";
	case 0xFF01: return "no boot-up after NMT reset";
	case 0xFF02: return "configuration refused by drive";
	case 0xFF03: return "drive restarted (boot-up while operational)";
	case 0xFF04: return "drive left Operational: NMT pre-operational";
	case 0xFF05: return "drive left Operational: NMT stopped";
	case 0xFF06: return "no TPDO from the drive";
	case 0xFF07: return "NMT start not confirmed";
	case 0xFF08: return "PDO COB-ID not supported";
	case 0xFF09: return "fault reset refused by drive";
	case 0x1000: return "drive in Fault without EMCY";
	default: return NULL;
	}
}

static int req_status(struct servod *sd, struct out *o, int argc, char **argv, char *msg, size_t n)
{
	struct amp_peer_info pi = { 0 };
	int32_t cmd[AMP_MAX_AXES], act[AMP_MAX_AXES];
	uint32_t ax_status[AMP_MAX_AXES], axes;
	struct sp_status s;
	uint64_t restores, recoveries;
	int peer, rc, open;

	(void)argc, (void)argv;
	pthread_mutex_lock(&sd->lock);
	open = session_open(&sd->session);
	peer = open ? amp_linux_peer(&sd->amp) : AMP_E_PEER_ABSENT;
	(void)amp_linux_peer_info((const void *)sd->ocm, sd->ocm_size, &pi);
	restores = sd->stats.restores;
	recoveries = sd->stats.recoveries;
	memcpy(cmd, sd->stats.cmd_pos, sizeof(cmd));
	memcpy(act, sd->stats.act_pos, sizeof(act));
	memcpy(ax_status, sd->stats.ax_status, sizeof(ax_status));
	pthread_mutex_unlock(&sd->lock);
	put(o, "remoteproc=%s\n", rproc_state(&sd->rproc));
	put(o, "session=%s epoch=%u\n", open ? "open" : session_latched(&sd->session) ? "fault" : "closed",
	    sd->session.epoch);
	put(o, "link=%s\n", peer == AMP_OK ? "attached" : amp_strerror(peer));
	put(o, "servo_state=%s fault=0x%08x (%s) servo_epoch=%u attach_count=%u\n",
	    sstate_name(pi.state), pi.fault, fault_name(pi.fault), pi.epoch, pi.attach_count);
	put(o, "period_us=%u axes=%u wd_limit=%u\n", sd->pset[SP_P_cycle_period_us], sd->pset[SP_P_axes],
	    sd->pset[SP_P_wd_limit]);
	put(o, "params_restored_attach=%u restores=%llu recoveries=%llu recovering=%d params_resend=%d\n",
	    sd->session.restored_attach, (unsigned long long)restores, (unsigned long long)recoveries,
	    session_recovering(&sd->session), sd->session.params_resend);
	supervisor_format(sd, o);
	/* each axis's drive: the internal model or a CiA 402 drive's state and error code */
	axes = sd->pset[SP_P_axes] < AMP_MAX_AXES ? sd->pset[SP_P_axes] : AMP_MAX_AXES;
	for (uint32_t i = 0; i < axes; i++) {
		const char *why = master_error(SP_AX_ERROR(ax_status[i]));

		put(o, "axis%u.drive=%s axis%u.error=0x%04x", i, drive_name(SP_AX_DRIVE(ax_status[i])), i,
		    SP_AX_ERROR(ax_status[i]));
		if (SP_AX_DRIVE(ax_status[i]) != SP_DRIVE_INTERNAL)	/* a CANopen drive's NMT state */
			put(o, " axis%u.nmt=%s", i, nmt_name(SP_AX_NMT(ax_status[i])));
		put(o, "\n");
		if (why)
			put(o, "axis%u.fault=%s\n", i, why);
	}
	prog_format_status(&sd->prog, o, cmd, act);
	if (session_latched(&sd->session)) {
		snprintf(msg, n, "fault latched (%s): the firmware is stopped; `ampctl fault reset` restarts it",
			 sd->recovery.latched_why);
		return SE_OFFLINE;
	}
	if (peer != AMP_OK) {
		snprintf(msg, n, "servo not running (remoteproc %s, link: %s)", rproc_state(&sd->rproc),
			 amp_strerror(peer));
		return SE_OFFLINE;
	}
	rc = servo_status(sd, &s, msg, n);
	if (rc)
		return rc;
	put(o, "servo_cycles=%u servo_missed=%u servo_overruns=%u safestops=%u stop_cycles=%u\n",
	    s.cycles, s.missed, s.overruns, s.safestops, s.stop_cycles);
	return SE_OK;
}
SERVOD_REQUEST("status", req_status);

static void put_linux(struct out *o, const struct cycle_stats *c, const struct amp_stats *as, uint32_t lcycle)
{
	put(o, "linux.wakes=%llu\n", (unsigned long long)c->wakes);
	put(o, "linux.cycles=%llu\n", (unsigned long long)c->cycles);
	put(o, "linux.exchanges=%llu\n", (unsigned long long)c->exchanges);
	put(o, "linux.absent=%llu\n", (unsigned long long)c->absent);
	put(o, "linux.missed_irq=%llu\n", (unsigned long long)c->missed_irq);
	put(o, "linux.uio_skips=%llu\n", (unsigned long long)c->uio_skips);
	put(o, "linux.late=%llu\n", (unsigned long long)c->late);
	put(o, "linux.stalls=%llu\n", (unsigned long long)c->stalls);
	put(o, "linux.peer_errors=%llu\n", (unsigned long long)c->peer_errors);
	put(o, "linux.last_stall_cycles=%u\nlinux.last_stall_us=%u\n", c->stall_cycles, c->stall_us);
	put(o, "linux.recoveries=%llu\n", (unsigned long long)c->recoveries);
	put(o, "linux.restores=%llu\n", (unsigned long long)c->restores);
	put(o, "linux.recovery_retries=%llu\nlinux.recovery_failures=%llu\nlinux.latches=%llu\n",
	    (unsigned long long)c->recovery_retries, (unsigned long long)c->recovery_failures,
	    (unsigned long long)c->latches);
	put(o, "linux.fb_fresh=%u\nlinux.fb_stale=%u\nlinux.fb_torn=%u\nlinux.fb_missed=%u\nlinux.fb_invalid=%u\n",
	    as->fresh, as->stale, as->torn, as->missed, as->invalid);
	put(o, "linux.peer_late=%u\nlinux.mbox_ok=%u\nlinux.mbox_err=%u\nlinux.sem_corrupt=%u\n", as->peer_late,
	    as->mbox_ok, as->mbox_err, as->sem_corrupt);
	put(o, "linux.amp_cycle=%u\nlinux.fb_servo_cycle=%u\nlinux.fb_cmd_seq=%u\n", lcycle, c->servo_cycle,
	    c->servo_cmd_seq);
	put(o, "linux.wake_lat_ns.min=%u\nlinux.wake_lat_ns.mean=%llu\nlinux.wake_lat_ns.max=%u\n", c->lat_min,
	    (unsigned long long)(c->lat_n ? c->lat_sum / c->lat_n : 0), c->lat_max);
	put(o, "linux.work_ns.mean=%llu\nlinux.work_ns.max=%u\n",
	    (unsigned long long)(c->cycles ? c->work_sum / c->cycles : 0), c->work_max);
	/* the sum too: a window's exact mean is the difference of two sums
	 * over that of linux.cycles (bench/cycle/cycle_bench.py) */
	put(o, "linux.work_ns.sum=%llu\n", (unsigned long long)c->work_sum);
	for (int b = 0; b < LAT_BUCKETS; b++) {
		if (b < LAT_BUCKETS - 1)
			put(o, "linux.wake_lat_hist.lt_%uus=%llu\n", lat_bucket_edges_us[b],
			    (unsigned long long)c->lat_hist[b]);
		else
			put(o, "linux.wake_lat_hist.ge_%uus=%llu\n", lat_bucket_edges_us[b - 1],
			    (unsigned long long)c->lat_hist[b]);
	}
}

static void put_telem(struct servod *sd, struct out *o, const struct telem_stats *ts)
{
	put(o, "telem.enabled=%d\n", sd->telem_on);
	if (!sd->telem_on)
		return;
	put(o, "telem.port=%u\ntelem.pushed=%llu\ntelem.dropped=%llu\ntelem.drained=%llu\n",
	    telem_port(&sd->telem), (unsigned long long)ts->pushed, (unsigned long long)ts->dropped,
	    (unsigned long long)ts->drained);
	put(o, "telem.events=%llu\ntelem.events_dropped=%llu\ntelem.client_lost=%llu\n",
	    (unsigned long long)ts->events, (unsigned long long)ts->events_dropped,
	    (unsigned long long)ts->client_lost);
	put(o, "telem.clients=%u\ntelem.clients_total=%llu\ntelem.bytes_sent=%llu\n"
	       "telem.ring_high_water=%u\n",
	    ts->clients, (unsigned long long)ts->clients_total, (unsigned long long)ts->bytes_sent,
	    ts->ring_high_water);
	put(o, "telem.auth_failed=%llu\ntelem.auth_timeout=%llu\ntelem.evicted=%llu\ntelem.refused=%llu\n"
	       "telem.stalled=%llu\ntelem.protocol=%llu\n",
	    (unsigned long long)ts->auth_failed, (unsigned long long)ts->auth_timeout,
	    (unsigned long long)ts->evicted, (unsigned long long)ts->refused,
	    (unsigned long long)ts->stalled, (unsigned long long)ts->protocol);
}

static void put_servo(struct out *o, const struct sp_status *s)
{
	put(o, "servo.state=%s\nservo.fault=0x%08x\nservo.cycles=%u\nservo.missed=%u\nservo.overruns=%u\n",
	    sstate_name(s->state), s->fault, s->cycles, s->missed, s->overruns);
	put(o, "servo.cmd_fresh=%u\nservo.cmd_stale=%u\nservo.cmd_torn=%u\nservo.cmd_missed=%u\nservo.cmd_invalid=%u\n",
	    s->rx_fresh, s->rx_stale, s->rx_torn, s->rx_missed, s->rx_invalid);
	put(o, "servo.linux_cycle=%u\nservo.attach_count=%u\nservo.period_us=%u\nservo.axes=%u\n", s->linux_cycle,
	    s->attach_count, s->period_us, s->axes);
	put(o, "servo.safestops=%u\nservo.stop_cycles=%u\nservo.mbox_served=%u\n", s->safestops, s->stop_cycles,
	    s->mbox_served);
	put(o, "servo.irq_lat_ns.max=%u\n", s->irq_lat_max_ns);
	put(o, "servo.cost_samples=%u\n", s->samples);
	put(o, "servo.rx_ticks.mean=%u\nservo.rx_ticks.max=%u\n", s->rx_ticks_mean, s->rx_ticks_max);
	put(o, "servo.ctrl_ticks.mean=%u\nservo.ctrl_ticks.max=%u\n", s->ctrl_ticks_mean, s->ctrl_ticks_max);
	put(o, "servo.tx_ticks.mean=%u\nservo.tx_ticks.max=%u\n", s->tx_ticks_mean, s->tx_ticks_max);
	put(o, "servo.cycle_ticks.mean=%u\nservo.cycle_ticks.max=%u\n", s->cycle_ticks_mean, s->cycle_ticks_max);
	put(o, "servo.svc_stack_used=%u\nservo.svc_stack_size=%u\n", s->svc_stack_used, s->svc_stack_size);
	put(o, "servo.irq_unhandled=%u\nservo.irq_disabled=%u\nservo.irq_disabled_last=%u\nservo.period_refused=%u\n",
	    s->irq_unhandled, s->irq_disabled, s->irq_disabled_last, s->period_refused);
}

static int req_stats(struct servod *sd, struct out *o, int argc, char **argv, char *msg, size_t n)
{
	struct sp_status s;
	struct cycle_stats c;
	struct amp_stats as;
	struct telem_stats ts;
	uint32_t lcycle;
	int rc;

	(void)argc, (void)argv;
	pthread_mutex_lock(&sd->lock);
	c = sd->stats;
	as = sd->amp.st;
	lcycle = sd->amp.cycle;
	if (sd->telem_on)	/* pushes happen under sd->lock: consistent with the counters */
		telem_get_stats(&sd->telem, &ts);
	pthread_mutex_unlock(&sd->lock);
	put_linux(o, &c, &as, lcycle);
	put_telem(sd, o, &ts);
	prog_format_stats(&sd->prog, o);
	rc = servo_status(sd, &s, msg, n);
	if (rc) {
		put(o, "servo.unavailable=1\n");
		return rc;
	}
	/*
	 * The servo's counters are read through the mailbox after servod's
	 * own: the number of cycles servod handled or counted as missed in
	 * between bounds how far apart the two halves of this snapshot are.
	 */
	pthread_mutex_lock(&sd->lock);
	put(o, "stats.skew_cycles=%llu\n",
	    (unsigned long long)((sd->stats.cycles + sd->stats.missed_irq) - (c.cycles + c.missed_irq)));
	pthread_mutex_unlock(&sd->lock);
	put_servo(o, &s);
	return SE_OK;
}
SERVOD_REQUEST("stats", req_stats);
