// SPDX-License-Identifier: MIT
/*
 * servod - the Linux side of the servo cycle (docs/cycle.md, section 2).
 *
 *   servod [-s SOCKET] [-p PARAMFILE] [-a AMPLITUDE_INC] [-f FREQ_HZ]
 *          [--ttc-hz HZ] [--servo-clock-hz HZ] [--prio N]
 *          [--telemetry ADDR:PORT|off] [--telemetry-token FILE] [--id CONTROLLER_ID]
 *          [--inc-per-mm N] [--vmax MM_S] [--amax MM_S2] [--travel MM]
 *          [--idle sine|hold] [--max-program-s S]
 *          [--recovery-limit K] [--recovery-window S] [--recovery-timeout S]
 *          [--recovery-backoff S] [-v]
 *   servod --find-rproc
 *
 * --find-rproc prints the servo core's remoteproc directory
 * (/sys/class/remoteproc/remoteprocN, found as servod finds it: rproc.h)
 * and exits: 0, or 1 when there is none. Guest scripts and the tests use
 * it instead of a fixed remoteprocN: RPROC=$(servod --find-rproc).
 *
 * Threads: the cycle thread (cycle.c, SCHED_FIFO) exchanges with the servo
 * at every cycle interrupt; the main thread runs the supervisor
 * (supervisor.c) and serves ampctl on the control socket (control.c) and
 * the telemetry's requests, one per pass, between two rounds of the
 * supervisor (telemetry.c); the
 * telemetry's drain thread, the firmware trace thread (fwtrace.c) and a
 * program's feeder thread (program_feed.c) run at normal priority. Every
 * function gets the one struct servod (context.h).
 */
#define _GNU_SOURCE
#include <errno.h>
#include <sched.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <sys/mman.h>

#include "context.h"

/* The one file-scope variable: what SIGINT / SIGTERM set (lock-free, so
 * async-signal-safe); every thread reads it through sd->quit. */
static atomic_int quit_requested;

static void on_signal(int sig)
{
	(void)sig;
	atomic_store(&quit_requested, 1);
}

static const struct servod_opts default_opts = {
	SERVOD_SOCKET, SERVOD_PARAMS, 2000.0, 0.5, 133000000u, 80, 0, 100000000u, "127.0.0.1:7700",
	"zynq7000_qemu", { 1000.0, 200.0, 2000.0, 500.0, 1000u, 0, PROG_MAX_S_DEFAULT }, "", TELEM_DEFAULT_PORT, NULL, { 0 }, 0,
	RECOVERY_CFG_DEFAULT,
};

static void usage(void)
{
	fprintf(stderr, "usage: servod [-s SOCKET] [-p PARAMFILE] [-a AMPLITUDE_INC] [-f FREQ_HZ] "
			"[--ttc-hz HZ] [--servo-clock-hz HZ] [--prio N] "
			"[--telemetry ADDR:PORT|off] [--telemetry-token FILE] [--id NAME] [--inc-per-mm N] [--vmax MM_S] "
			"[--amax MM_S2] [--travel MM] [--idle sine|hold] [--max-program-s S] [--recovery-limit K] "
			"[--recovery-window S] [--recovery-timeout S] [--recovery-backoff S] [-v]\n"
			"       servod --find-rproc\n");
}

/* Seconds (decimals allowed) as ms into *ms, within (0, 86400]: 0, or 1. */
static int parse_secs(const char *v, uint32_t *ms)
{
	char *end;
	double s = strtod(v, &end);

	if (!*v || *end || !(s > 0.0 && s <= 86400.0))
		return 1;
	*ms = (uint32_t)(s * 1000.0 + 0.5);
	return *ms ? 0 : 1;
}

/* The bounds on recovery (recovery.h): 0, or 1 with the reason on stderr. */
static int parse_recovery(struct recovery_cfg *c, const char *a, const char *v, int *known)
{
	char *end;

	*known = 1;
	if (!strcmp(a, "--recovery-limit")) {
		unsigned long k = strtoul(v, &end, 10);

		if (!*v || *end || k > RECOVERY_HISTORY_MAX) {
			fprintf(stderr, "servod: --recovery-limit wants 0 (no fault latch) .. %u restarts\n",
				RECOVERY_HISTORY_MAX);
			return 1;
		}
		c->limit = (uint32_t)k;
		return 0;
	}
	if (!strcmp(a, "--recovery-window") || !strcmp(a, "--recovery-timeout") || !strcmp(a, "--recovery-backoff")) {
		uint32_t *ms = !strcmp(a, "--recovery-window") ? &c->window_ms :
			       !strcmp(a, "--recovery-timeout") ? &c->timeout_ms : &c->backoff_ms;

		if (parse_secs(v, ms)) {
			fprintf(stderr, "servod: %s wants seconds > 0 (at most 86400), not '%s'\n", a, v);
			return 1;
		}
		return 0;
	}
	*known = 0;
	return 0;
}

/* 0, or 1 with the reason on stderr. */
static int parse_options(struct servod_opts *o, int argc, char **argv)
{
	for (int i = 1; i < argc; i++) {
		const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : 0;
		int known;

		if (!strcmp(a, "-v")) {
			o->verbose = 1;
			continue;
		}
		if (!v)
			goto bad;
		if (parse_recovery(&o->recovery, a, v, &known))
			return 1;
		if (known) {
			i++;
			continue;
		}
		if (!strcmp(a, "-s"))
			o->sock_path = v;
		else if (!strcmp(a, "-p"))
			o->param_path = v;
		else if (!strcmp(a, "-a"))
			o->amplitude = atof(v);
		else if (!strcmp(a, "-f"))
			o->freq = atof(v);
		else if (!strcmp(a, "--ttc-hz"))
			o->ttc_hz = (uint32_t)strtoul(v, 0, 0);
		else if (!strcmp(a, "--servo-clock-hz"))
			o->servo_clock_hz = (uint32_t)strtoul(v, 0, 0);
		else if (!strcmp(a, "--prio"))
			o->prio = atoi(v);
		else if (!strcmp(a, "--telemetry"))
			o->telem = v;
		else if (!strcmp(a, "--telemetry-token"))
			o->telem_token_file = v;
		else if (!strcmp(a, "--id"))
			o->id = v;
		else if (!strcmp(a, "--inc-per-mm"))
			o->prog.inc_per_mm = atof(v);
		else if (!strcmp(a, "--vmax"))
			o->prog.vmax = atof(v);
		else if (!strcmp(a, "--amax"))
			o->prog.amax = atof(v);
		else if (!strcmp(a, "--travel"))
			o->prog.travel = atof(v);
		else if (!strcmp(a, "--max-program-s"))
			o->prog.max_s = (uint32_t)strtoul(v, 0, 0);
		else if (!strcmp(a, "--idle") && !strcmp(v, "hold"))
			o->prog.idle_hold = 1;
		else if (!strcmp(a, "--idle") && !strcmp(v, "sine"))
			o->prog.idle_hold = 0;
		else
			goto bad;
		i++;
	}
	if (!(o->prog.inc_per_mm > 0 && o->prog.vmax > 0 && o->prog.amax > 0 && o->prog.travel > 0 &&
	      o->prog.max_s > 0)) {
		fprintf(stderr, "servod: --inc-per-mm, --vmax, --amax, --travel and --max-program-s must be > 0\n");
		return 1;
	}
	if (telemetry_parse_opt(o)) {
		fprintf(stderr, "servod: --telemetry wants ADDR:PORT, [ADDR6]:PORT or off, not '%s'\n", o->telem);
		return 1;
	}
	if (telemetry_check_access(o))
		return 1;
	return 0;
bad:
	usage();
	return 1;
}

/* The OCM region and the cycle interrupt: 0, or 1 (logged). */
static int open_devices(struct servod *sd)
{
	uint32_t size, offs;

	sd->board_lock_fd = uio_open(sd, "ocm-mailbox", &sd->ocm, &size, &offs);
	if (sd->board_lock_fd < 0) {
		logm(sd, "no UIO device for the OCM mailbox (ocm-mailbox)");
		return 1;
	}
	/* one servod per board: the lock on the OCM device, taken before
	 * anything is touched (cycle interrupt, socket, region); the kernel
	 * drops it when this servod ends, however it ends */
	if (flock(sd->board_lock_fd, LOCK_EX | LOCK_NB)) {
		if (errno == EWOULDBLOCK)
			logm(sd, "another servod is running on this board (it holds the OCM mailbox device): "
				 "exiting, nothing touched");
		else
			logm(sd, "flock on the OCM mailbox device: %s", strerror(errno));
		return 1;
	}
	sd->ocm += offs;
	sd->ocm_size = size - offs;
	if (cycle_irq_open(sd, &sd->irq, sd->opt.ttc_hz)) {
		logm(sd, "no UIO device for the cycle interrupt (cycle-interrupt)");
		return 1;
	}
	if (rproc_find(&sd->rproc))
		logm(sd, "no remoteproc yet (the one the OCM mailbox's devicetree node names, or %s)", RPROC_NAME);
	return 0;
}

/* SCHED_FIFO at --prio, or normal priority when that is refused: 0 or 1. */
static int start_cycle_thread(struct servod *sd, pthread_t *th)
{
	struct sched_param sp = { .sched_priority = sd->opt.prio };
	pthread_attr_t attr;
	int rc;

	pthread_attr_init(&attr);
	pthread_attr_setinheritsched(&attr, PTHREAD_EXPLICIT_SCHED);
	pthread_attr_setschedpolicy(&attr, SCHED_FIFO);
	pthread_attr_setschedparam(&attr, &sp);
	rc = pthread_create(th, &attr, cycle_thread, sd);
	if (rc) {
		logm(sd, "SCHED_FIFO thread: %s; running the cycle at normal priority", strerror(rc));
		rc = pthread_create(th, 0, cycle_thread, sd);
		if (rc) {
			logm(sd, "pthread_create: %s", strerror(rc));
			return 1;
		}
	}
	return 0;
}

static struct servod *servod_new(void)
{
	size_t size = (sizeof(struct servod) + 63u) & ~(size_t)63u;
	struct servod *sd = aligned_alloc(64, size);

	if (sd)
		memset(sd, 0, size);
	return sd;
}

/* servod --find-rproc: the servo core's remoteproc directory on stdout. */
static int find_rproc(void)
{
	struct rproc rp = { 0 };

	if (rproc_find(&rp)) {
		fprintf(stderr, "servod: no remoteproc for the servo core (neither the one the %s UIO "
				"device's servoamp,remoteproc names, nor one named %s)\n",
			RPROC_MAILBOX_UIO, RPROC_NAME);
		return 1;
	}
	printf("%s\n", rp.dir);
	return 0;
}

int main(int argc, char **argv)
{
	struct servod *sd = servod_new();
	pthread_mutexattr_t ma;
	pthread_t th;
	int rc, busy = 0;

	if (!sd)
		return 1;
	if (argc == 2 && !strcmp(argv[1], "--find-rproc"))
		return find_rproc();
	sd->opt = default_opts;
	sd->quit = &quit_requested;
	sd->irq.fd = -1;
	sd->listen_fd = -1;
	cycle_stats_new_session(&sd->stats);
	if (parse_options(&sd->opt, argc, argv))
		return 1;
	setvbuf(stderr, 0, _IOLBF, 0);
	params_load(sd);
	sd->period_ns = sd->pset[SP_P_cycle_period_us] * 1000u;
	sd->axes = sd->pset[SP_P_axes];
	sd->opt.prog.period_us = sd->pset[SP_P_cycle_period_us];
	if (open_devices(sd))
		return 1;

	pthread_mutexattr_init(&ma);
	pthread_mutexattr_setprotocol(&ma, PTHREAD_PRIO_INHERIT);
	pthread_mutex_init(&sd->lock, &ma);
	prog_init(&sd->prog, &sd->opt.prog, &sd->lock);

	signal(SIGINT, on_signal);
	signal(SIGTERM, on_signal);
	signal(SIGPIPE, SIG_IGN);
	if (mlockall(MCL_CURRENT | MCL_FUTURE))
		logm(sd, "mlockall: %s", strerror(errno));
	telemetry_start(sd);
	if (start_cycle_thread(sd, &th))
		return 1;
	if (control_listen(sd)) {
		logm(sd, "socket %s: %s", sd->opt.sock_path, strerror(errno));
		return 1;
	}
	if (sd->telem_on) {
		rc = fwtrace_start(sd);
		if (rc)
			logw(sd, "firmware trace thread: %s", strerror(rc));
	}
	logm(sd, "running: cycle thread SCHED_FIFO %d, socket %s, parameters %s, period %u us, %u axes",
	     sd->opt.prio, sd->opt.sock_path, sd->opt.param_path, sd->pset[SP_P_cycle_period_us],
	     sd->pset[SP_P_axes]);
	logm(sd, "recovery: at most %u restart(s) within %g s, then the fault latch (0: none); a restarted "
		 "firmware attaches within %g s; a failed restart is retried after %g s, doubled each time, "
		 "at most %g s",
	     sd->opt.recovery.limit, sd->opt.recovery.window_ms / 1000.0, sd->opt.recovery.timeout_ms / 1000.0,
	     sd->opt.recovery.backoff_ms / 1000.0,
	     (sd->opt.recovery.backoff_max_ms > sd->opt.recovery.backoff_ms ? sd->opt.recovery.backoff_max_ms :
	      sd->opt.recovery.backoff_ms) / 1000.0);

	while (!servod_quitting(sd))
		servod_pass(sd, &busy);
	logm(sd, "exiting: closing the link (the servo brings its axes to a safe stop)");
	pthread_join(th, 0);	/* the cycle thread sees quit within 100 ms */
	pthread_mutex_lock(&sd->lock);
	if (session_has_region(&sd->session))
		amp_linux_close(&sd->amp);
	pthread_mutex_unlock(&sd->lock);
	control_close(sd);
	fwtrace_join(sd);
	telemetry_stop(sd);
	return 0;
}
