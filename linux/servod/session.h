/* SPDX-License-Identifier: MIT */
/*
 * session.h - the session state machine: what servod knows of the link
 * with the servo (docs/cycle.md, "The session").
 *
 *   CLOSED      no region of ours: amp_linux_init() waits until remoteproc
 *               says the servo is offline (start, or after a stop), or
 *               says it runs again after servod closed its own region
 *               (a firmware started since waits for a region)
 *   OPEN        region initialised (a new epoch), the servo not yet seen
 *               running by remoteproc
 *   RUNNING     remoteproc has said "running" in this session
 *   RECOVERING  servod reported a stall to remoteproc and restarts the
 *               firmware (recovery.h), which re-attaches in the same epoch
 *   FAULT       the fault latch: too many restarts within the window
 *               (recovery.h); the firmware is stopped, nothing is
 *               exchanged, until the operator's `ampctl fault reset`
 *
 * The cycle thread exchanges while the session is open: neither CLOSED nor
 * FAULT (FAULT keeps the region and its epoch for the restart after the
 * reset).
 */
#ifndef SERVOD_SESSION_H
#define SERVOD_SESSION_H

#include <stdatomic.h>
#include <stdint.h>
#include <time.h>

enum session_state {
	SESSION_CLOSED,
	SESSION_OPEN,
	SESSION_RUNNING,
	SESSION_RECOVERING,
	SESSION_FAULT,
};

enum session_event {
	SEV_REGION_READY,	/* amp_linux_init() done (remoteproc: offline) */
	SEV_SEEN_RUNNING,	/* remoteproc says "running" */
	SEV_SEEN_OFFLINE,	/* remoteproc says "offline" */
	SEV_CRASH_REPORTED,	/* a stall reported through report_crash */
	SEV_ATTACHED,		/* the servo attached and has the parameter set */
	SEV_LATCHED,		/* one restart too many within the window: the fault latch */
	SEV_RESET,		/* the operator's `ampctl fault reset`: restart */
	SEV_STOPPED,		/* stopped on request (remoteproc "offline" while a
				 * restart waited for the attach or its retry): the
				 * recovery abandoned, a new session for the next start */
};

/* What the cycle thread saw (session.stall_pending): 0 nothing. */
enum stall_why {
	STALL_HEARTBEAT = 1,	/* AMP_E_STALLED: heartbeat still for wd_limit cycles */
	STALL_PEER_ERROR = 2,	/* AMP_E_PEER_ERROR (FAULT or garbage state) for wd_limit cycles */
};

struct session {
	enum session_state state;	/* written under sd->lock by the main thread */
	uint32_t epoch;			/* of the region servod initialised (0: none
					 * yet; CLOSED with one: servod closed it when
					 * the servo stopped, close_session()) */
	uint32_t restored_attach;	/* attach_count whose parameters were loaded */
	int params_resend;		/* the servo may hold other values than servod's set (params_resend()) */
	uint32_t resend_tries;		/* failed tries since params_resend was set */
	uint64_t resend_ns;		/* the last try (mono_now_ns) */
	int waiting_logged;		/* CLOSED: "waiting until it is offline" said once */
	/* RUNNING, remoteproc "offline": an attach not yet loaded, as last
	 * seen (supervisor.c, start_under_way()) */
	uint32_t uw_attach, uw_hb;	/* its attach_count and heartbeat */
	uint64_t uw_seen_ns;		/* mono_now_ns: first seen */
	uint64_t uw_still_ns;		/* its heartbeat last moved */
	int uw_logged;			/* "a start under way" said for it */
	atomic_int stall_pending;	/* the cycle thread saw a stall: report it (enum stall_why) */
};

/* The state after ev in state s (unchanged when ev does not apply). */
enum session_state session_next(enum session_state s, enum session_event ev);
/* Applies ev: the caller holds sd->lock when it opens or closes the session. */
void session_event(struct session *ss, enum session_event ev);

/* The cycle thread exchanges, the mailbox posts. */
static inline int session_open(const struct session *ss)
{
	return ss->state != SESSION_CLOSED && ss->state != SESSION_FAULT;
}

/* The region is servod's (initialised, not yet closed): open or FAULT. */
static inline int session_has_region(const struct session *ss)
{
	return ss->state != SESSION_CLOSED;
}

static inline int session_latched(const struct session *ss)
{
	return ss->state == SESSION_FAULT;
}

static inline int session_recovering(const struct session *ss)
{
	return ss->state == SESSION_RECOVERING;
}

#endif
