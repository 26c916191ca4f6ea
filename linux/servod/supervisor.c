// SPDX-License-Identifier: MIT
/*
 * supervisor.c - the supervisor (main thread, every pass of the main loop):
 * follows remoteproc's view of the servo through the session state machine
 * (session.h), initialises the region while the servo is offline (or
 * runs again after servod closed its region), closes it when the servo
 * stops, reports a stall the cycle thread saw to remoteproc (report_crash, where
 * the driver has it; the upstream R5 driver has not: the stall is then
 * servod's own record) and restarts the firmware itself through
 * remoteproc's state (stop, start), within the bounds of recovery.h: a
 * failed restart is retried with backoff, one restart too many within the
 * window latches a fault (fault.c: the firmware left stopped) until the
 * operator's "fault reset". It loads the parameter set into the servo
 * after every attach.
 */
#define _GNU_SOURCE
#include <errno.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "context.h"

/* How long a restart waits for remoteproc's crash handler after a report. */
#define CRASH_WAIT_MS 1000u

/*
 * remoteproc's "offline" lags a start: the state says "running" once the
 * driver's start op returns, and the firmware may attach before that (the
 * Zynq-7000's driver waits for the firmware's RUN!, which it writes just
 * before its first attach). An attach in this epoch that servod has not
 * loaded yet, RUNNING, whose heartbeat moved within LINE_STILL_MS (over two
 * of the longest cycle period, 10 ms), is such a start: the session goes
 * on. Not for longer than START_UNDER_WAY_MS: a firmware that beats while
 * remoteproc says "offline" for that long is no start.
 */
#define LINE_STILL_MS		25u
#define START_UNDER_WAY_MS	2000u

/* Under sd->lock: 1 if the servo line shows a start under way. */
static int start_under_way(struct servod *sd, uint64_t now)
{
	struct session *ss = &sd->session;
	struct amp_peer_info pi = { 0 };

	(void)amp_linux_peer_info((const void *)sd->ocm, sd->ocm_size, &pi);
	if (pi.epoch != ss->epoch || pi.state != AMP_SSTATE_RUNNING || pi.attach_count == ss->restored_attach)
		return 0;
	if (pi.attach_count != ss->uw_attach) {
		ss->uw_attach = pi.attach_count;
		ss->uw_seen_ns = now;
		ss->uw_logged = 0;
	} else if (pi.heartbeat == ss->uw_hb) {
		return now - ss->uw_still_ns < LINE_STILL_MS * 1000000ull;
	}
	ss->uw_hb = pi.heartbeat;
	ss->uw_still_ns = now;
	return now - ss->uw_seen_ns < START_UNDER_WAY_MS * 1000000ull;
}

/*
 * The servo stopped (remoteproc "offline"; or offline while a restart
 * waited): the session closes, and so does its region (the Linux line says
 * STOPPED). A firmware started before servod's next pass then waits for a
 * new region instead of attaching to this one, where Linux no longer beats:
 * its watchdog would take it to its safe stop (LINUX_STALL) within wd_limit
 * cycles, before servod could take it back (12 of 150 stops and starts in
 * one shell line at 4 kHz on the Zynq-7000). Unless the new firmware has
 * attached already (start_under_way()): 0 then, the session goes on.
 */
static int close_session(struct servod *sd, enum session_event ev)
{
	struct session *ss = &sd->session;

	pthread_mutex_lock(&sd->lock);
	if (ev == SEV_SEEN_OFFLINE && start_under_way(sd, mono_now_ns())) {
		pthread_mutex_unlock(&sd->lock);
		return 0;
	}
	session_event(ss, ev);
	if (ss->state == SESSION_CLOSED)
		amp_linux_close(&sd->amp);
	pthread_mutex_unlock(&sd->lock);
	return 1;
}

/*
 * CLOSED: a new region (epoch) once remoteproc says the servo is offline,
 * or says it runs again after servod closed its own region (a stop and a
 * start between two passes: that firmware waits for a region, it cannot
 * attach to a closed one). Anything else running is not servod's to touch
 * until it is offline.
 */
static void open_session(struct servod *sd, const char *rs)
{
	struct session *ss = &sd->session;
	int offline = !strcmp(rs, "offline"), rc;

	if (!offline && !(ss->epoch && !strcmp(rs, "running"))) {
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
		ss->uw_attach = 0;	/* attach counts start again: none seen */
		/* a stall the cycle thread saw in the session before (the
		 * operator's stop came first) is not the next firmware's */
		atomic_store(&ss->stall_pending, 0);
		cycle_stats_new_session(&sd->stats);
	}
	pthread_mutex_unlock(&sd->lock);
	if (rc == AMP_OK)
		logm(sd, "servo %s: region initialised, epoch %u, wd_limit %u; waiting for the servo",
		     offline ? "offline" : "started again before servod made a new region", ss->epoch,
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

static int rs_is(const char *rs, const char *what)
{
	return !strcmp(rs, what);
}

/* remoteproc holds the firmware powered: a "stop" applies */
int supervisor_rs_powered(const char *rs)
{
	return rs_is(rs, "running") || rs_is(rs, "crashed") || rs_is(rs, "attached");
}

/* The servo's line read into pi: 1 if it says STOPPING in this region's
 * epoch (the firmware saw remoteproc's stop, docs/cycle.md "An operator's
 * stop"). */
static int servo_says_stopping(const struct servod *sd, struct amp_peer_info *pi)
{
	*pi = (struct amp_peer_info){ 0 };
	(void)amp_linux_peer_info((const void *)sd->ocm, sd->ocm_size, pi);
	return pi->epoch == sd->amp.epoch && pi->state == AMP_SSTATE_STOPPING;
}

/* servod is not stopping or starting the firmware itself: a stop seen now
 * is someone else's (no restart, or one waiting for its attach). */
static int own_restart_idle(const struct recovery *r)
{
	return r->phase == RESTART_NONE || r->phase == RESTART_ATTACH;
}

/* A recovery over (the servo back, or stopped on request). */
static void recovery_over(struct recovery *r)
{
	r->phase = RESTART_NONE;
	r->failed = 0;
	r->restart = 0;
	r->by_reset = 0;
}

/* ms as seconds for a log line: "60 s", "0.25 s" */
const char *supervisor_secs(char *buf, size_t n, uint64_t ms)
{
	snprintf(buf, n, "%g s", (double)ms / 1000.0);
	return buf;
}

/*
 * Once its instance is known: what the driver offers, said once in the log.
 *
 * report_crash (servoamp's Zynq-7000 driver): a stall is reported there,
 * remoteproc's record of the crash ("crashed", its crash count, the
 * coredump). The upstream xlnx_r5_remoteproc has none: nothing reports a
 * crash to remoteproc, the stall is servod's own record (its log, the
 * counters of `ampctl stats`), and the restart below is the same.
 *
 * remoteproc's own recovery off: servod stops and starts the firmware
 * itself. A recovery that fails in the kernel leaves remoteproc "offline"
 * with the firmware's power reference still held: a "start" then does
 * nothing and a "stop" is refused, so nothing could retry it. With
 * recovery disabled a crash report leaves the state "crashed", which
 * "stop" takes back to "offline". The upstream R5 driver disables it at
 * probe already (it reports no crash of its own either): read, not written.
 */
static void own_recovery(struct servod *sd, const char *rs)
{
	struct recovery *r = &sd->recovery;
	char path[600], cur[32];

	if (rs_is(rs, "absent")) {
		r->kernel_recovery_off = 0;	/* the instance may come back anew */
		return;
	}
	if (r->kernel_recovery_off)
		return;
	r->kernel_recovery_off = 1;
	sd->rproc.report_crash = rproc_has(&sd->rproc, "device/report_crash");
	if (!sd->rproc.report_crash)
		logm(sd, "%s: no device/report_crash (a driver without servoamp's crash report): a stall is "
			 "servod's own record (log, `ampctl stats`), remoteproc is not told; servod restarts the "
			 "firmware through state (stop, start)", sd->rproc.dir);
	if (!rproc_has(&sd->rproc, "recovery")) {
		logm(sd, "%s: no recovery attribute: remoteproc's own recovery left as the driver set it",
		     sd->rproc.dir);
		return;
	}
	if (!rproc_read_recovery(&sd->rproc, cur, sizeof(cur), path, sizeof(path)) && rs_is(cur, "disabled")) {
		logm(sd, "remoteproc's own recovery is disabled (%s): servod restarts the firmware after a stall",
		     path);
		return;
	}
	if (rproc_write_recovery(&sd->rproc, "disabled", path, sizeof(path)))
		logw(sd, "%s: %s: remoteproc's own recovery stays enabled (it restarts the firmware too)", path,
		     strerror(errno));
	else
		logm(sd, "remoteproc's own recovery disabled (%s): servod restarts the firmware after a stall", path);
}

/* A restart's stop is next: which attach servod itself stops. */
void supervisor_note_stop_phase(struct servod *sd)
{
	struct amp_peer_info pi = { 0 };

	(void)amp_linux_peer_info((const void *)sd->ocm, sd->ocm_size, &pi);
	sd->recovery.stopped_attach = pi.attach_count;
	sd->recovery.phase = RESTART_STOP;
}

/* A restart begins now (its stop next), or the fault latches: 1 or 0. */
static int begin_restart(struct servod *sd, const char *rs, uint64_t now, const char *cause)
{
	struct recovery *r = &sd->recovery;

	if (!recovery_may_restart(r, &sd->opt.recovery, now)) {
		supervisor_latch(sd, rs, cause);
		return 0;
	}
	recovery_note_restart(r, now);
	r->restart++;
	supervisor_note_stop_phase(sd);
	r->phase_ns = now;
	return 1;
}

/* The restart did not bring the servo back: the next one after the
 * backoff, or the latch when it would be one too many. */
static void restart_failed(struct servod *sd, const char *rs, const char *fmt, ...) SERVOD_PRINTF(3, 4);
static void restart_failed(struct servod *sd, const char *rs, const char *fmt, ...)
{
	struct recovery *r = &sd->recovery;
	const struct recovery_cfg *c = &sd->opt.recovery;
	uint64_t now = mono_now_ns(), wait, retry;
	char cause[300], w[32], b[32];
	va_list ap;

	va_start(ap, fmt);
	vsnprintf(r->last_failure, sizeof(r->last_failure), fmt, ap);
	va_end(ap);
	r->failed++;
	pthread_mutex_lock(&sd->lock);
	sd->stats.recovery_failures++;
	pthread_mutex_unlock(&sd->lock);
	wait = recovery_backoff_ns(c, r->failed);
	retry = now + wait;
	snprintf(cause, sizeof(cause), "restart %u failed (%s)", r->restart, r->last_failure);
	if (!recovery_may_restart(r, c, retry)) {
		logw(sd, "recovery: %s", cause);
		supervisor_latch(sd, rs, cause);
		return;
	}
	r->phase = RESTART_BACKOFF;
	r->retry_ns = retry;
	r->backoff_powered = supervisor_rs_powered(rproc_state(&sd->rproc));
	logw(sd, "recovery: %s: retry in %s (%u of %u restarts within %s used)", cause,
	     supervisor_secs(b, sizeof(b), wait / 1000000u), recovery_in_window(r, c, now), c->limit,
	     supervisor_secs(w, sizeof(w), c->window_ms));
}

/*
 * A stop on request, not a crash (docs/cycle.md, "An operator's stop"):
 * the firmware's state word says STOPPING (it writes that when it sees
 * remoteproc's stop, before its heartbeat ends), or remoteproc, read
 * again now, says "offline" (a driver that powers the core down without
 * asking the firmware: the heartbeat stood still because the operator
 * stopped it). With remoteproc's own recovery off, a crash leaves
 * "crashed", never "offline". Never counted, never restarted.
 */
static int stopped_on_request(struct servod *sd, const char **rs, char *what, size_t n)
{
	struct amp_peer_info pi = { 0 };

	*rs = rproc_state(&sd->rproc);
	if (servo_says_stopping(sd, &pi)) {
		snprintf(what, n, "the firmware says it is stopping on request (remoteproc: %s)", *rs);
		return 1;
	}
	if (rs_is(*rs, "offline")) {
		snprintf(what, n, "remoteproc says offline: stopped through remoteproc");
		return 1;
	}
	return 0;
}

/* The cycle thread saw the servo's heartbeat stand still, or its state
 * word say FAULT (or nothing sane) for wd_limit cycles: reported to
 * remoteproc (its record of the crash) where the driver has report_crash,
 * then servod restarts the
 * firmware, which re-attaches; or, one restart too many, the latch. A
 * restarted servo that stalls before its parameter set is loaded is a
 * failed restart. */
static void report_stall(struct servod *sd, int why, const char *rs)
{
	struct amp_peer_info pi = { 0 };
	uint64_t now = mono_now_ns();
	char path[600], cause[200], what[120];

	if (why == STALL_PEER_ERROR) {
		(void)amp_linux_peer_info((const void *)sd->ocm, sd->ocm_size, &pi);
		if (pi.epoch != sd->amp.epoch)
			snprintf(cause, sizeof(cause),
				 "servo line corrupt (epoch word 0x%08x, this region's is %u) for %u cycles", pi.epoch,
				 sd->amp.epoch, sd->pset[SP_P_wd_limit]);
		else
			snprintf(cause, sizeof(cause), "servo faulted (state word 0x%08x, fault 0x%08x) for %u cycles",
				 pi.state, pi.fault, sd->pset[SP_P_wd_limit]);
	} else {
		snprintf(cause, sizeof(cause), "servo stalled (heartbeat still for %u cycles)",
			 sd->pset[SP_P_wd_limit]);
	}
	/* remoteproc and the firmware asked again before anything is
	 * reported (not while servod's own restart stops and starts it) */
	if (own_restart_idle(&sd->recovery) && stopped_on_request(sd, &rs, what, sizeof(what))) {
		logm(sd, "%s, but %s: not a crash, not restarted", cause, what);
		return;
	}
	if (session_recovering(&sd->session)) {
		logw(sd, "%s: the restarted firmware stalled before its parameter set was loaded", cause);
		restart_failed(sd, rs, "%s after its attach", cause);
		return;
	}
	if (!recovery_may_restart(&sd->recovery, &sd->opt.recovery, now)) {
		logw(sd, "%s: not restarted", cause);
		supervisor_latch(sd, rs, cause);
		return;
	}
	if (!sd->rproc.report_crash) {
		logw(sd, "%s: restarting the firmware (servod's record: the driver has no report_crash)", cause);
	} else {
		logw(sd, "%s: reporting a crash to remoteproc", cause);
		if (rproc_report_crash(&sd->rproc, path, sizeof(path)))
			logw(sd, "%s: %s (servod restarts the firmware all the same)", path, strerror(errno));
		else
			sd->recovery.crash_wait = 1;
	}
	pthread_mutex_lock(&sd->lock);
	session_event(&sd->session, SEV_CRASH_REPORTED);
	sd->stats.recoveries++;
	cycle_stats_publish(&sd->stats, &sd->pub);
	pthread_mutex_unlock(&sd->lock);
	(void)begin_restart(sd, rs, now, cause);
}

/*
 * RECOVERING, and remoteproc says "offline" though servod did not stop the
 * firmware: while a restarted firmware is awaited (servod's start
 * succeeded) or a failed one waits for its retry (it was left powered),
 * only a stop through remoteproc's state takes it offline. The operator's
 * stop ends the recovery: nothing restarted, nothing counted. 1 if so.
 */
static int stopped_while_recovering(struct servod *sd, const char *rs)
{
	struct recovery *r = &sd->recovery;
	struct amp_peer_info pi = { 0 };

	if (!rs_is(rs, "offline"))
		return 0;
	/* awaited: the restarted firmware attached (another attach than the
	 * one servod stopped) and said it stops on request; without that
	 * word (stopped before its attach, or a driver that powers it down
	 * unasked) "offline" is a failed restart, retried */
	if (r->phase == RESTART_ATTACH && !(servo_says_stopping(sd, &pi) && pi.attach_count != r->stopped_attach))
		return 0;
	if (r->phase != RESTART_ATTACH && !(r->phase == RESTART_BACKOFF && r->backoff_powered))
		return 0;
	logm(sd, "servo stopped through remoteproc during recovery (restart %u, %s): recovery abandoned, "
		 "not restarted", r->restart, recovery_phase_name(r->phase));
	recovery_over(r);
	(void)close_session(sd, SEV_STOPPED);
	return 1;
}

/* RECOVERING: one step of the restart, at most one write to remoteproc's
 * state per pass (a write returns once remoteproc has stopped or started
 * the firmware, or failed to). */
static void restart_step(struct servod *sd, const char *rs)
{
	struct recovery *r = &sd->recovery;
	const struct recovery_cfg *c = &sd->opt.recovery;
	uint64_t now = mono_now_ns(), timeout = (uint64_t)c->timeout_ms * 1000000u;
	char path[600], t[32];

	switch (r->phase) {
	case RESTART_NONE:
		return;
	case RESTART_BACKOFF: {
		char cause[300];

		if ((int64_t)(now - r->retry_ns) < 0)
			return;
		snprintf(cause, sizeof(cause), "restart %u failed (%s)", r->restart, r->last_failure);
		if (!begin_restart(sd, rs, now, cause))
			return;
		pthread_mutex_lock(&sd->lock);
		sd->stats.recovery_retries++;
		pthread_mutex_unlock(&sd->lock);
		logm(sd, "recovery: restart %u (retry %u)", r->restart, r->failed);
		return;
	}
	case RESTART_STOP:
		/*
		 * After a crash report the stop waits (at most CRASH_WAIT_MS)
		 * until remoteproc's crash handler, a work item, has said
		 * "crashed": a stop before it makes the handler skip the crash,
		 * and a handler run after the start would mark the new firmware
		 * crashed (a failed restart, retried).
		 */
		if (r->crash_wait && rs_is(rs, "running") &&
		    now - r->phase_ns < (uint64_t)CRASH_WAIT_MS * 1000000u)
			return;
		r->crash_wait = 0;
		if (supervisor_rs_powered(rs)) {
			if (rproc_write_state(&sd->rproc, "stop", path, sizeof(path))) {
				restart_failed(sd, rs, "stop: %s: %s", path, strerror(errno));
			} else {
				r->phase = RESTART_START;
				r->phase_ns = now;
			}
			return;
		}
		if (!rs_is(rs, "offline")) {
			if (now - r->phase_ns > timeout)
				restart_failed(sd, rs, "remoteproc %s, not stopped within %s", rs,
					       supervisor_secs(t, sizeof(t), c->timeout_ms));
			return;
		}
		r->phase = RESTART_START;	/* offline already: the start in this pass */
		r->phase_ns = now;
		/* fall through */
	case RESTART_START:
		if (rs_is(rs, "offline")) {
			if (rproc_write_state(&sd->rproc, "start", path, sizeof(path))) {
				restart_failed(sd, rs, "start: %s: %s", path, strerror(errno));
			} else {
				r->phase = RESTART_ATTACH;
				r->phase_ns = now;
			}
		} else if (rs_is(rs, "running")) {
			r->phase = RESTART_ATTACH;
			r->phase_ns = now;
		} else if (now - r->phase_ns > timeout) {
			restart_failed(sd, rs, "remoteproc %s after the stop", rs);
		}
		return;
	case RESTART_ATTACH:
		if (rs_is(rs, "crashed") || rs_is(rs, "offline"))
			restart_failed(sd, rs, "remoteproc %s after the start", rs);
		else if (now - r->phase_ns > timeout)
			restart_failed(sd, rs, "started, but not attached within %s",
				       supervisor_secs(t, sizeof(t), c->timeout_ms));
		return;
	}
}

/* A new attach (first start, restart, recovery): the parameter set. */
static void restore(struct servod *sd, uint32_t attach_count)
{
	struct session *ss = &sd->session;
	struct recovery *r = &sd->recovery;
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
	if (recovery) {
		if (r->by_reset)
			logm(sd, "recovery complete: the servo is back after the operator's fault reset");
		else
			logm(sd, "recovery complete (restart %u%s)", r->restart,
			     r->restart > 1 ? ", after retries" : "");
		recovery_over(r);
	}
	logm(sd, "servo attached (epoch %u, attach_count %u): parameter set loaded", ss->epoch, attach_count);
}

void supervise(struct servod *sd)
{
	struct session *ss = &sd->session;
	const char *rs = rproc_state(&sd->rproc);
	struct amp_peer_info pi;
	int peer, why;

	own_recovery(sd, rs);
	if (session_latched(ss)) {
		supervisor_latched_pass(sd, rs);
		return;
	}
	if (!session_open(ss)) {
		open_session(sd, rs);
		return;
	}
	if (!strcmp(rs, "running"))
		event_locked(sd, SEV_SEEN_RUNNING);
	if (!strcmp(rs, "offline") && ss->state == SESSION_RUNNING) {
		int stopping = servo_says_stopping(sd, &pi);

		if (close_session(sd, SEV_SEEN_OFFLINE)) {
			logm(sd, "servo went offline%s",
			     stopping ? " (stopped on request: its last state word is STOPPING)" : "");
		} else if (!ss->uw_logged) {
			logm(sd, "servo offline but attached again to this servod's region (attach_count %u): "
				 "a start under way, the session goes on", ss->uw_attach);
			ss->uw_logged = 1;
		}
		return;
	}
	why = atomic_exchange(&ss->stall_pending, 0);
	if (why)
		report_stall(sd, why, rs);
	if (session_recovering(ss) && stopped_while_recovering(sd, rs))
		return;
	if (session_recovering(ss)) {
		restart_step(sd, rs);
		rs = rproc_state(&sd->rproc);	/* after a stop or a start */
	}
	if (!session_open(ss))	/* latched */
		return;
	pthread_mutex_lock(&sd->lock);
	peer = amp_linux_peer(&sd->amp);
	(void)amp_linux_peer_info((const void *)sd->ocm, sd->ocm_size, &pi);
	pthread_mutex_unlock(&sd->lock);
	if (peer == AMP_E_PEER_STOPPING && sd->recovery.stopping_logged != pi.attach_count + 1u &&
	    own_restart_idle(&sd->recovery)) {
		sd->recovery.stopping_logged = pi.attach_count + 1u;
		logm(sd, "servo stopping on request (its state word says STOPPING, remoteproc: %s): not a stall, "
			 "not restarted", rs);
	}
	/* a restart takes the attach it waits for (ATTACH), not the one of a
	 * firmware whose stall this pass made a failed restart (BACKOFF) */
	if (peer == AMP_OK && pi.attach_count != ss->restored_attach && strcmp(rs, "running") == 0 &&
	    (!session_recovering(ss) || sd->recovery.phase == RESTART_ATTACH))
		restore(sd, pi.attach_count);
	else if (peer == AMP_OK && ss->params_resend && !session_recovering(ss) && strcmp(rs, "running") == 0)
		params_resend(sd);
}

void servod_pass(struct servod *sd, int *busy)
{
	supervise(sd);
	control_serve(sd, *busy ? 0 : 20);
	*busy = telemetry_serve(sd);
}
