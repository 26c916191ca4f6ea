// SPDX-License-Identifier: MIT
/*
 * supervisor.c - the supervisor (main thread, every 20 ms): follows
 * remoteproc's view of the servo through the session state machine
 * (session.h), initialises the region only while the servo is offline,
 * reports a stall the cycle thread saw to remoteproc (report_crash), and
 * loads the parameter set into the servo after every attach.
 */
#define _GNU_SOURCE
#include <errno.h>
#include <string.h>
#include <time.h>

#include "context.h"

/* CLOSED: a new region (epoch) once remoteproc says the servo is offline. */
static void open_session(struct servod *sd, const char *rs)
{
	struct session *ss = &sd->session;
	int rc;

	if (strcmp(rs, "offline")) {
		if (!ss->waiting_logged) {
			logm(sd, "servo %s but not attached to this servod: waiting until it is offline", rs);
			ss->waiting_logged = 1;
		}
		return;
	}
	pthread_mutex_lock(&sd->lock);
	rc = amp_linux_init(&sd->amp, (void *)sd->ocm, sd->ocm_size, sd->pset[SP_P_wd_limit]);
	if (rc == AMP_OK) {
		session_event(ss, SEV_REGION_READY);
		ss->epoch = sd->amp.epoch;
		ss->restored_attach = 0;
		cycle_stats_new_session(&sd->stats);
	}
	pthread_mutex_unlock(&sd->lock);
	if (rc == AMP_OK)
		logm(sd, "servo offline: region initialised, epoch %u, wd_limit %u; waiting for the servo", ss->epoch,
		     sd->pset[SP_P_wd_limit]);
	else
		logm(sd, "amp_linux_init: %s", amp_strerror(rc));
	ss->waiting_logged = 0;
}

static void event_locked(struct servod *sd, enum session_event ev)
{
	pthread_mutex_lock(&sd->lock);
	session_event(&sd->session, ev);
	pthread_mutex_unlock(&sd->lock);
}

/* The cycle thread saw the servo's heartbeat stand still, or its state
 * word say FAULT (or nothing sane) for wd_limit cycles: remoteproc's
 * recovery stops and restarts the firmware, which re-attaches. */
static void report_stall(struct servod *sd, int why)
{
	struct amp_peer_info pi = { 0 };
	char path[600];

	if (why == STALL_PEER_ERROR) {
		(void)amp_linux_peer_info((const void *)sd->ocm, sd->ocm_size, &pi);
		if (pi.epoch != sd->amp.epoch)
			logw(sd, "servo line corrupt (epoch word 0x%08x, this region's is %u) for %u cycles: reporting a crash to remoteproc",
			     pi.epoch, sd->amp.epoch, sd->pset[SP_P_wd_limit]);
		else
			logw(sd, "servo faulted (state word 0x%08x, fault 0x%08x) for %u cycles: reporting a crash to remoteproc",
			     pi.state, pi.fault, sd->pset[SP_P_wd_limit]);
	} else {
		logw(sd, "servo stalled (heartbeat still for %u cycles): reporting a crash to remoteproc",
		     sd->pset[SP_P_wd_limit]);
	}
	if (rproc_report_crash(&sd->rproc, path, sizeof(path))) {
		logm(sd, "%s: %s", path, strerror(errno));
		return;
	}
	pthread_mutex_lock(&sd->lock);
	session_event(&sd->session, SEV_CRASH_REPORTED);
	sd->stats.recoveries++;
	cycle_stats_publish(&sd->stats, &sd->pub);
	pthread_mutex_unlock(&sd->lock);
	clock_gettime(CLOCK_MONOTONIC, &sd->session.recover_t0);
}

/* A new attach (first start, restart, recovery): the parameter set. */
static void restore(struct servod *sd, uint32_t attach_count)
{
	struct session *ss = &sd->session;
	int recovery = session_recovering(ss);
	uint64_t cycle, stall_cycle;
	char msg[256];
	int rc = params_restore(sd, msg, sizeof(msg));

	if (rc != SE_OK) {
		pthread_mutex_lock(&sd->lock);
		sd->stats.restore_errors++;
		pthread_mutex_unlock(&sd->lock);
		logm(sd, "parameter restore failed: %s", msg);
		return;
	}
	pthread_mutex_lock(&sd->lock);
	ss->restored_attach = attach_count;
	sd->stats.restores++;
	cycle_stats_publish(&sd->stats, &sd->pub);
	cycle = sd->stats.cycles;
	stall_cycle = sd->stats.stall_cycle;
	session_event(ss, SEV_ATTACHED);
	pthread_mutex_unlock(&sd->lock);
	telemetry_attach(sd, recovery, stall_cycle, cycle);
	if (recovery)
		logm(sd, "recovery complete");
	logm(sd, "servo attached (epoch %u, attach_count %u): parameter set loaded", ss->epoch, attach_count);
}

void supervise(struct servod *sd)
{
	struct session *ss = &sd->session;
	const char *rs = rproc_state(&sd->rproc);
	struct amp_peer_info pi;
	int peer, why;

	if (!session_open(ss)) {
		open_session(sd, rs);
		return;
	}
	if (session_recovering(ss)) {
		struct timespec t;

		clock_gettime(CLOCK_MONOTONIC, &t);
		if (t.tv_sec - ss->recover_t0.tv_sec > RECOVERY_TIMEOUT_S) {
			logm(sd, "recovery: servo not back after 20 s; giving up on it");
			event_locked(sd, SEV_RECOVERY_TIMEOUT);
		}
	}
	if (!strcmp(rs, "running"))
		event_locked(sd, SEV_SEEN_RUNNING);
	if (!strcmp(rs, "offline") && ss->state == SESSION_RUNNING) {
		event_locked(sd, SEV_SEEN_OFFLINE);
		logm(sd, "servo went offline");
		return;
	}
	why = atomic_exchange(&ss->stall_pending, 0);
	if (why)
		report_stall(sd, why);
	pthread_mutex_lock(&sd->lock);
	peer = amp_linux_peer(&sd->amp);
	(void)amp_linux_peer_info((const void *)sd->ocm, sd->ocm_size, &pi);
	pthread_mutex_unlock(&sd->lock);
	if (peer == AMP_OK && pi.attach_count != ss->restored_attach && strcmp(rs, "running") == 0)
		restore(sd, pi.attach_count);
	else if (peer == AMP_OK && ss->params_resend && !session_recovering(ss) && strcmp(rs, "running") == 0)
		params_resend(sd);
}
