/* SPDX-License-Identifier: MIT */
/*
 * context.h - struct servod: everything servod knows, one instance made by
 * main() and passed by pointer to every function (docs/cycle.md, section
 * 2). Which file does what:
 *
 *   main.c          options, start-up, the main loop, shut-down
 *   cycle.c         the cycle thread: one exchange per cycle interrupt
 *   cycle_irq.c     the cycle interrupt (UIO "cycle-interrupt", TTC1 counter 1)
 *   cycle_stats.c   the counters, their one publication for the telemetry
 *   setpoint.c      the setpoint sources (sine, program) behind an ops table
 *   program.c       the G-code runner: cycle part, control part, run/stop
 *   program_feed.c  the runner's feeder thread (dry run, streaming)
 *   path_error.c    a run's path and following error
 *   session.c       the session state machine
 *   supervisor.c    the supervisor: remoteproc, session, crash report, restarts,
 *                   restore
 *   fault.c         the fault latch, "fault [reset]", the recovery status lines
 *   recovery.c      the bounds on recovery: restarts in a window, backoff
 *   params.c        the parameter set: file, servo, "param" request
 *   mailbox.c       requests to the servo; "raw", "resume", "debug"
 *   report.c        "status" and "stats"
 *   control.c       the control socket and the request table
 *   rproc.c         remoteproc in sysfs: lookup, state, report_crash, trace
 *   fwtrace.c       the firmware's trace lines forwarded as telemetry LOG
 *   telemetry.c     the telemetry transport (linux/telemetry) set-up
 *   uio.c, sysfs.c, log.c   small helpers (the clock: servoamp/mono_clock.h)
 *
 * Locking: sd->lock (priority inheritance) is taken by the cycle thread for
 * its whole cycle after the wake-up; it protects the link (amp), the
 * session state, the counters (stats), period_ns and axes, and the
 * program runner's playback. The main thread is the only other writer.
 */
#ifndef SERVOD_CONTEXT_H
#define SERVOD_CONTEXT_H

#include <pthread.h>
#include <stdatomic.h>
#include <stdint.h>

#include "amp/amp.h"
#include "servoamp/mono_clock.h"
#include "control.h"
#include "cycle_irq.h"
#include "cycle_stats.h"
#include "fwtrace.h"
#include "log.h"
#include "mailbox.h"
#include "params.h"
#include "program.h"
#include "recovery.h"
#include "rproc.h"
#include "servoamp/servo_proto.h"
#include "servod.h"
#include "session.h"
#include "setpoint.h"
#include "sysfs.h"
#include "telem.h"
#include "uio.h"

struct servod_opts {
	const char *sock_path;
	const char *param_path;
	double amplitude;		/* inc */
	double freq;			/* Hz */
	uint32_t ttc_hz;
	int prio;
	int verbose;
	uint32_t servo_clock_hz;	/* rate of the feedback's t_cycle / irq_latency ticks */
	const char *telem;		/* ADDR:PORT or "off" */
	const char *id;			/* controller id in the telemetry HELLO */
	struct prog_opts prog;		/* G-code runner: scale, planner limits, idle mode */
	char telem_addr[64];		/* from telem */
	uint16_t telem_port;
	const char *telem_token_file;	/* --telemetry-token FILE, or NULL */
	unsigned char telem_token[TELEM_TOKEN_MAX];	/* its contents */
	uint32_t telem_token_len;
	struct recovery_cfg recovery;	/* --recovery-limit, -window, -timeout, -backoff */
};

struct servod {
	/* telemetry first: the struct is 64-byte aligned */
	struct telem telem;
	int telem_on;
	struct servod_opts opt;
	const atomic_int *quit;		/* set by SIGINT / SIGTERM */

	pthread_mutex_t lock;
	struct amp_linux amp;
	volatile uint8_t *ocm;		/* the region (UIO "ocm-mailbox") */
	uint32_t ocm_size;
	uint32_t period_ns;		/* cycle period (parameter cycle_period_us) */
	uint32_t axes;			/* axes exchanged (parameter axes) */
	uint32_t pset[SP_P_COUNT];	/* the authoritative parameter set (params.h) */

	struct session session;
	struct recovery recovery;	/* restarts, the fault latch (main thread only) */
	struct cycle_stats stats;
	struct cycle_stats_pub pub;
	struct cycle_irq irq;
	struct rproc rproc;
	struct fwtrace trace;
	struct prog_runner prog;
	int listen_fd;
	struct control_client clients[CONTROL_CLIENTS];	/* control.c */
	int board_lock_fd;		/* the OCM UIO device, flock()ed: one servod per board */
};

static inline int servod_quitting(const struct servod *sd)
{
	return atomic_load_explicit(sd->quit, memory_order_relaxed);
}

/* The cycle thread (cycle.c). */
void *cycle_thread(void *arg);
/* One round of the supervisor (supervisor.c): main thread, every pass of
 * the main loop (at least every 20 ms). */
void supervise(struct servod *sd);
/*
 * One pass of the main loop (supervisor.c): the supervisor, the control
 * socket (its poll waits up to 20 ms, or not at all while *busy), at most
 * TELEMETRY_REQUESTS_PER_PASS telemetry requests (*busy: one was served).
 * A client that keeps requests in flight never keeps the supervisor out.
 */
void servod_pass(struct servod *sd, int *busy);
/* The recovery lines of `ampctl status` and `ampctl fault` (fault.c). */
void supervisor_format(struct servod *sd, struct out *o);
/* The supervisor's pieces shared with fault.c (main thread): one restart
 * too many latches the fault (why: its cause), every pass while latched,
 * a restart's stop next (the attach it stops noted), remoteproc's state
 * holding the firmware powered, ms as seconds for a log line. */
void supervisor_latch(struct servod *sd, const char *rs, const char *why);
void supervisor_latched_pass(struct servod *sd, const char *rs);
void supervisor_note_stop_phase(struct servod *sd);
int supervisor_rs_powered(const char *rs);
const char *supervisor_secs(char *buf, size_t n, uint64_t ms);
/* Telemetry (telemetry.c). */
int telemetry_parse_opt(struct servod_opts *o);
int telemetry_check_access(struct servod_opts *o);
void telemetry_start(struct servod *sd);
void telemetry_cycle(struct servod *sd, const struct cycle_wake *w, int rc, const struct amp_rx_info *rx,
		     const struct amp_cmd_axis *cmd, uint32_t n);
void telemetry_attach(struct servod *sd, int recovery, uint64_t stall_cycle, uint64_t cycle);
/* REQUEST frames ("param ..."), at most TELEMETRY_REQUESTS_PER_PASS per
 * call (main thread): 1 if it served one (more may wait), else 0. */
#define TELEMETRY_REQUESTS_PER_PASS 1
int telemetry_serve(struct servod *sd);
void telemetry_stop(struct servod *sd);

#endif
