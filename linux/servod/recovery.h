/* SPDX-License-Identifier: MIT */
/*
 * recovery.h - the bounds on servod's recovery of the servo (docs/cycle.md,
 * "Recovery and the fault latch"), as a start limit does for a service or a
 * fault latch for a drive:
 *
 *   - every restart of the firmware servod begins (after a stall or a crash,
 *     and every retry of a restart that failed) is counted; before it begins
 *     one, servod looks at how many it began within the last window_ms: at
 *     limit already, it latches a fault instead (the firmware is left
 *     stopped, nothing is exchanged, `ampctl status` says why) until the
 *     operator's `ampctl fault reset`;
 *   - a restart fails when the firmware cannot be stopped or started through
 *     remoteproc, or does not attach within timeout_ms of its start; it is
 *     retried after backoff_ms, doubled at each failure in a row, at most
 *     backoff_max_ms.
 *
 * The functions here decide, from the times they are given (ns of
 * CLOCK_MONOTONIC); the supervisor (supervisor.c) acts.
 */
#ifndef SERVOD_RECOVERY_H
#define SERVOD_RECOVERY_H

#include <stdint.h>

#define RECOVERY_HISTORY_MAX 32u	/* the largest limit */

struct recovery_cfg {
	uint32_t limit;			/* restarts within window_ms before the latch; 0: no latch */
	uint32_t window_ms;
	uint32_t timeout_ms;		/* a started firmware must attach within this */
	uint32_t backoff_ms;		/* before the first retry of a failed restart */
	uint32_t backoff_max_ms;
};

/* 3 restarts within 60 s; 10 s to attach; retries after 1, 2, 4 ... 30 s. */
#define RECOVERY_CFG_DEFAULT { 3u, 60000u, 10000u, 1000u, 30000u }

/* Where a restart is (the session is RECOVERING while it is not NONE). */
enum restart_phase {
	RESTART_NONE,		/* nothing to bring back */
	RESTART_STOP,		/* stop the firmware (state "stop"), unless offline already */
	RESTART_START,		/* start it (state "start") */
	RESTART_ATTACH,		/* started: waiting for its attach and its parameter set */
	RESTART_BACKOFF,	/* the restart failed: the next one at retry_ns */
};

struct recovery {
	enum restart_phase phase;
	uint64_t phase_ns;		/* when the phase began */
	uint64_t retry_ns;		/* BACKOFF: when the next restart begins */
	uint32_t failed;		/* restarts failed in a row (the backoff's exponent) */
	uint32_t restart;		/* restarts begun since the last attach (1: the first) */
	int by_reset;			/* this restart is the operator's fault reset */
	uint64_t hist[RECOVERY_HISTORY_MAX];	/* when restarts began (a ring) */
	uint32_t nhist;			/* restarts in hist (at most RECOVERY_HISTORY_MAX) */
	uint32_t hist_next;
	char last_failure[200];		/* why the last restart failed */
	/* the latch (session FAULT) */
	uint64_t latched_ns;
	char latched_why[400];
	int stop_pending;		/* latched, the firmware not yet stopped */
	uint64_t stop_retry_ns;
	int foreign_logged;		/* latched and running: "not ours" said once */
	int kernel_recovery_off;	/* remoteproc's own recovery disabled (supervisor.c) */
	int crash_wait;			/* a crash was reported: the stop waits for "crashed" */
	int backoff_powered;		/* BACKOFF began with the firmware powered (running) */
	uint32_t stopped_attach;	/* the servo's attach_count when servod's restart stopped it */
	uint32_t stopping_logged;	/* attach_count + 1 whose "stopping on request" was logged */
};

/* Restarts begun within the window that ends at at_ns. */
uint32_t recovery_in_window(const struct recovery *r, const struct recovery_cfg *c, uint64_t at_ns);
/* 1 if one more restart begun at at_ns stays within the limit. */
int recovery_may_restart(const struct recovery *r, const struct recovery_cfg *c, uint64_t at_ns);
/* A restart begins at now_ns: counted. */
void recovery_note_restart(struct recovery *r, uint64_t now_ns);
/* The wait before the retry after the n-th failed restart in a row (n >= 1). */
uint64_t recovery_backoff_ns(const struct recovery_cfg *c, uint32_t n);
/* The operator's reset: the history and the failures forgotten. */
void recovery_clear(struct recovery *r);
/* "none", "stop", "start", "attach", "backoff". */
const char *recovery_phase_name(enum restart_phase p);

#endif
