// SPDX-License-Identifier: MIT
/* fault.c - the fault latch: one restart too many latches it (the firmware
 * stopped, nothing exchanged), the recovery lines of `ampctl status` and
 * the operator's "fault [reset]". When it latches: supervisor.c. */
#define _GNU_SOURCE
#include <stdio.h>
#include <errno.h>
#include <string.h>

#include "context.h"

/* Latched: the firmware stopped (again, after a stop that failed). */
static void latched_stop(struct servod *sd, const char *rs)
{
	struct recovery *r = &sd->recovery;
	char path[600];

	if (!supervisor_rs_powered(rs)) {
		r->stop_pending = 0;
		return;
	}
	if ((int64_t)(mono_now_ns() - r->stop_retry_ns) < 0)
		return;
	if (rproc_write_state(&sd->rproc, "stop", path, sizeof(path))) {
		r->stop_retry_ns = mono_now_ns() + recovery_backoff_ns(&sd->opt.recovery, 1);
		logw(sd, "fault latched: stopping the firmware: %s: %s (tried again in %llu ms)", path, strerror(errno),
		     (unsigned long long)(recovery_backoff_ns(&sd->opt.recovery, 1) / 1000000u));
		return;
	}
	r->stop_pending = 0;
	logm(sd, "fault latched: firmware stopped");
}

/* One restart too many within the window: the session FAULT, the
 * firmware stopped, nothing exchanged until the operator's reset. */
void supervisor_latch(struct servod *sd, const char *rs, const char *why)
{
	struct recovery *r = &sd->recovery;
	const struct recovery_cfg *c = &sd->opt.recovery;
	uint64_t now = mono_now_ns();
	char w[32];

	pthread_mutex_lock(&sd->lock);
	session_event(&sd->session, SEV_LATCHED);
	sd->stats.latches++;
	pthread_mutex_unlock(&sd->lock);
	r->phase = RESTART_NONE;
	r->latched_ns = now;
	snprintf(r->latched_why, sizeof(r->latched_why), "%s; %u restarts within %s (limit %u)", why,
		 recovery_in_window(r, c, now), supervisor_secs(w, sizeof(w), c->window_ms), c->limit);
	logw(sd, "fault latched: %s: the firmware is stopped and the axes disabled until `ampctl fault reset`",
	     r->latched_why);
	r->stop_pending = 1;
	r->stop_retry_ns = now;
	r->foreign_logged = 0;
	latched_stop(sd, rs);
}

/* Latched, every pass: the stop retried if it failed; a firmware someone
 * else started is not servod's (nothing exchanged) until the reset. */
void supervisor_latched_pass(struct servod *sd, const char *rs)
{
	struct recovery *r = &sd->recovery;

	atomic_store(&sd->session.stall_pending, 0);
	if (r->stop_pending) {
		latched_stop(sd, rs);
		return;
	}
	if (!supervisor_rs_powered(rs)) {
		r->foreign_logged = 0;
		return;
	}
	if (!r->foreign_logged) {
		logw(sd, "fault latched: remoteproc says %s (started by someone else?): servod does not exchange "
			 "with the servo until `ampctl fault reset`", rs);
		r->foreign_logged = 1;
	}
}

void supervisor_format(struct servod *sd, struct out *o)
{
	const struct recovery *r = &sd->recovery;
	const struct recovery_cfg *c = &sd->opt.recovery;
	uint64_t now = mono_now_ns();

	put(o, "recovery=%s restart=%u restarts_in_window=%u restart_limit=%u window_s=%g failed_in_a_row=%u",
	    recovery_phase_name(r->phase), r->restart, recovery_in_window(r, c, now), c->limit,
	    (double)c->window_ms / 1000.0, r->failed);
	if (r->phase == RESTART_BACKOFF)
		put(o, " next_restart_in_ms=%llu",
		    (unsigned long long)((int64_t)(r->retry_ns - now) > 0 ? (r->retry_ns - now) / 1000000u : 0u));
	put(o, "\n");
	if (r->last_failure[0])
		put(o, "last_restart_failure=%s\n", r->last_failure);
	if (session_latched(&sd->session))
		put(o, "latched=1 latched_for_s=%.1f firmware_stopped=%d\nlatched_why=%s\n",
		    (double)(now - r->latched_ns) / 1e9, !r->stop_pending, r->latched_why);
	else
		put(o, "latched=0\n");
}

/*
 * "fault": the recovery lines of `ampctl status`. "fault reset": the
 * operator's reset of a latched fault (a drive's fault reset, systemd's
 * reset-failed): the restart history forgotten, the firmware started again
 * (stopped first if someone started it meanwhile); the session RECOVERING
 * until it attaches and has its parameter set ("recovery complete").
 * Without a latched fault it only forgets the history of restarts.
 */
static int req_fault(struct servod *sd, struct out *o, int argc, char **argv, char *msg, size_t n)
{
	struct recovery *r = &sd->recovery;
	char why[sizeof(r->latched_why)];
	double ago;

	if (argc == 1) {
		supervisor_format(sd, o);
		return SE_OK;
	}
	if (argc != 2 || strcmp(argv[1], "reset")) {
		snprintf(msg, n, "usage: fault [reset]");
		return SE_USAGE;
	}
	if (!session_latched(&sd->session)) {
		if (r->phase == RESTART_NONE) {
			recovery_clear(r);
			put(o, "fault: none latched; the history of restarts is cleared\n");
		} else {
			put(o, "fault: none latched; a recovery is running (restart %u, %s)\n", r->restart,
			    recovery_phase_name(r->phase));
		}
		return SE_OK;
	}
	snprintf(why, sizeof(why), "%s", r->latched_why);
	ago = (double)(mono_now_ns() - r->latched_ns) / 1e9;
	recovery_clear(r);
	r->by_reset = 1;
	r->restart = 1;
	supervisor_note_stop_phase(sd);
	r->phase_ns = mono_now_ns();
	pthread_mutex_lock(&sd->lock);
	session_event(&sd->session, SEV_RESET);
	pthread_mutex_unlock(&sd->lock);
	logm(sd, "fault reset by the operator (latched %.1f s ago: %s): restarting the servo", ago, why);
	put(o, "fault reset: restarting the servo (recovering=1 in `ampctl status` until it is back)\n");
	return SE_OK;
}
SERVOD_REQUEST("fault", req_fault);
