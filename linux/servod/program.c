// SPDX-License-Identifier: MIT
/*
 * program.c - servod's G-code runner: the cycle thread's part, the control
 * thread's part and the "run" / "stop" requests (program.h, docs/cycle.md).
 *
 * Pipeline axes X, Y, Z drive servo axes 0, 1, 2 (as many as the servo
 * has); the other servo axes hold the position they had when the run
 * started. Scale: opt.inc_per_mm servo increments per program millimetre
 * (the pipeline's increments_per_mm), default 1000: 1 increment = 1 um.
 */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "context.h"

#define PREFILL 256u		/* setpoints ready before the run starts */
#define SETTLE_CYCLES 200u	/* hold before the run starts (axes settle from the sine) */

static const char *const mode_name[] = { "sine", "hold", "armed", "run", "stopping" };
static const char *const result_name[] = { "none", "checking", "running", "done", "stopped",
					   "fault", "refused" };

void prog_init(struct prog_runner *pr, const struct prog_opts *o, pthread_mutex_t *cycle_lock)
{
	pr->opt = *o;
	pr->cycle_lock = cycle_lock;
	pr->prog_fd = -1;
	pr->on_queues = NULL;	/* telemetry_start sets it, after this */
	pr->on_queues_user = NULL;
	/* cannot fail: queue_buf is aligned and sized for PROG_QUEUE_N */
	if (ring_init_buf(&pr->queue, pr->queue_buf, sizeof(pr->queue_buf), sizeof(struct motion_setpoint),
			  PROG_QUEUE_N))
		abort();
	pthread_mutex_init(&pr->info_lock, 0);
	atomic_store(&pr->mode, o->idle_hold ? PM_HOLD : PM_SINE);
	pr->play.resync = o->idle_hold;
}

/* ---- cycle thread --------------------------------------------------------------- */

int prog_driving(struct prog_runner *pr)
{
	return atomic_load_explicit(&pr->mode, memory_order_acquire) != PM_SINE || atomic_load(&pr->req_hold);
}

int prog_on_sine(struct prog_runner *pr)
{
	return atomic_load_explicit(&pr->mode, memory_order_acquire) == PM_SINE;
}

void prog_end_run(struct prog_runner *pr, int res)
{
	atomic_store(&pr->result, res);
	atomic_store(&pr->mode, PM_HOLD);
	path_error_end(&pr->play.pe);
	atomic_store(&pr->feeder_abort, 1);
}

static void set_prog_cmd(struct prog_playback *p, struct amp_cmd_axis *cmd, uint32_t n, const int32_t *pos,
			 const int32_t *vel)
{
	for (uint32_t i = 0; i < n && i < PROG_AXES; i++) {
		p->hold_pos[i] = pos[i];
		cmd[i].target_pos = pos[i];
		cmd[i].vel_ff = vel ? vel[i] : 0;
	}
}

/* RUN: one setpoint per cycle; an empty queue holds the last one (underrun). */
static void run_cycle(struct prog_runner *pr, struct amp_cmd_axis *cmd, uint32_t n)
{
	struct prog_playback *p = &pr->play;
	const struct motion_setpoint *sp;

	p->prog_cycles++;
	sp = ring_front(&pr->queue);
	if (!sp) {
		p->underruns++;	/* hold the last setpoint for this cycle */
		set_prog_cmd(p, cmd, n, p->cur.pos, 0);
		return;
	}
	p->cur = *sp;
	ring_release(&pr->queue);
	p->setpoints_used++;
	p->line = p->cur.line;
	set_prog_cmd(p, cmd, n, p->cur.pos, p->cur.vel);
	if (p->cur.status == MOTION_ST_DONE)
		prog_end_run(pr, PR_DONE);
	else if (p->cur.status == MOTION_ST_FAULT || p->cur.status == MOTION_ST_UNDERRUN)
		prog_end_run(pr, PR_FAULT);
}

/* STOPPING: the program's own path, time-scaled: the position advances by
 * stop_s setpoints per cycle, interpolated between cur and the next. */
static void stop_cycle(struct prog_runner *pr, struct amp_cmd_axis *cmd, uint32_t n)
{
	struct prog_playback *p = &pr->play;
	const struct motion_setpoint *nx;
	int32_t pos[PROG_AXES];

	p->prog_cycles++;
	p->stop_s -= p->stop_ds;
	if (p->stop_s < 1e-9)
		p->stop_s = 0.0;
	p->stop_f += p->stop_s;
	while (p->stop_f >= 1.0) {
		nx = ring_front(&pr->queue);
		if (!nx || nx->status != MOTION_ST_MOVING) {
			p->stop_f = 0.0;
			break;
		}
		p->cur = *nx;
		ring_release(&pr->queue);
		p->stop_f -= 1.0;
	}
	nx = ring_front(&pr->queue);
	for (uint32_t i = 0; i < PROG_AXES; i++) {
		double b = (nx && nx->status == MOTION_ST_MOVING) ? nx->pos[i] : p->cur.pos[i];

		pos[i] = (int32_t)lround(p->cur.pos[i] + p->stop_f * (b - p->cur.pos[i]));
	}
	p->line = p->cur.line;
	set_prog_cmd(p, cmd, n, pos, 0);
	if (p->stop_s == 0.0)
		prog_end_run(pr, PR_STOPPED);
}

/* The mode of this cycle after the requests and the arming condition. */
static int next_mode(struct prog_runner *pr, const struct amp_cmd_axis *cmd, uint32_t n, uint32_t seq)
{
	struct prog_playback *p = &pr->play;
	int m = atomic_load_explicit(&pr->mode, memory_order_acquire);

	if (m == PM_SINE && atomic_load(&pr->req_hold)) {
		for (uint32_t i = 0; i < n; i++)
			p->hold_pos[i] = cmd[i].target_pos;
		p->have_hold = 1;
		m = PM_HOLD;
		atomic_store(&pr->mode, m);
		atomic_store(&pr->req_hold, 0);
	}
	if (m == PM_ARMED) {
		if (atomic_load(&pr->req_stop)) {
			prog_end_run(pr, PR_STOPPED);
			m = PM_HOLD;
		} else if (++p->armed_cycles >= SETTLE_CYCLES &&
			   (ring_count(&pr->queue) >= PREFILL || atomic_load(&pr->feeder_done))) {
			m = PM_RUN;
			path_error_start(&p->pe, seq);
			atomic_store(&pr->mode, m);
		}
	}
	if (m == PM_RUN && atomic_load(&pr->req_stop)) {
		double v2 = 0;

		for (uint32_t i = 0; i < PROG_AXES; i++)
			v2 += (double)p->cur.vel[i] * (double)p->cur.vel[i];
		/* speed factor 1 -> 0 in N cycles: N = v / (amax T) */
		double ncyc = ceil(sqrt(v2) / (pr->opt.amax * pr->opt.inc_per_mm * pr->opt.period_us * 1e-6));
		p->stop_ds = 1.0 / (ncyc < 1.0 ? 1.0 : ncyc);
		p->stop_s = 1.0;
		p->stop_f = 0.0;
		m = PM_STOPPING;
		atomic_store(&pr->mode, m);
	}
	return m;
}

void prog_cycle(struct prog_runner *pr, struct amp_cmd_axis *cmd, uint32_t n, uint32_t seq)
{
	struct prog_playback *p = &pr->play;
	int m;

	if (n > AMP_MAX_AXES)	/* hold_pos[] has AMP_MAX_AXES */
		n = AMP_MAX_AXES;
	m = next_mode(pr, cmd, n, seq);

	if (m == PM_SINE)
		return;	/* the sine stays (the hold was withdrawn) */
	if (m == PM_RUN) {
		run_cycle(pr, cmd, n);
	} else if (m == PM_STOPPING) {
		stop_cycle(pr, cmd, n);
	} else {
		for (uint32_t i = 0; i < n; i++) {
			cmd[i].target_pos = p->hold_pos[i];
			cmd[i].vel_ff = 0;
		}
	}
	for (uint32_t i = PROG_AXES; i < n; i++)	/* axes beyond Z: the position they had */
		cmd[i].target_pos = p->hold_pos[i], cmd[i].vel_ff = 0;
	if (!p->have_hold)	/* position unknown (start, servo restart): */
		for (uint32_t i = 0; i < n; i++)	/* axes disabled until the next feedback */
			cmd[i].control_word = 0;
	path_error_command(&p->pe, seq, p->line, cmd, n);
}

static int running(int m);

/* The servo cannot follow (why: 1 link lost, 2 safe stop, 3 servo fault, 4 a drive's fault): a running
 * program ends in fault and the hold position is resynchronised from the
 * next fresh feedback. */
static void lose_servo(struct prog_runner *pr, int m, int why)
{
	if (m == PM_ARMED || m == PM_RUN || m == PM_STOPPING) {
		atomic_store(&pr->link_lost, why);
		prog_end_run(pr, PR_FAULT);
	}
	if (m != PM_SINE) {
		pr->play.resync = 1;
		pr->play.have_hold = 0;
	}
}

void prog_feedback(struct prog_runner *pr, int rc, const struct amp_fb_record *fb, uint32_t n, int fresh)
{
	struct prog_playback *p = &pr->play;
	int m = atomic_load_explicit(&pr->mode, memory_order_relaxed);
	uint32_t nfb;

	if (rc != AMP_OK) {
		/* servo gone, stalled, restarting, or its state word says
		 * FAULT (or nothing sane): a running program ends, the axes
		 * are disabled and the next sane feedback resynchronises the
		 * hold position */
		lose_servo(pr, m, rc == AMP_E_PEER_ERROR ? 3 : 1);
		return;
	}
	if (!fresh)
		return;
	if (n > AMP_MAX_AXES)
		n = AMP_MAX_AXES;
	/* the axes the record covers (amp_lib bounds its count) */
	nfb = fb->n_axes < n ? fb->n_axes : n;
	if (nfb && (fb->axis[0].status_word & SP_AX_SAFESTOP)) {
		lose_servo(pr, m, 2);
		return;
	}
	/* a CAN drive in fault (or gone silent) ends a run like a servo fault */
	for (uint32_t i = 0; i < nfb && running(m); i++) {
		uint32_t sw = fb->axis[i].status_word, d = SP_AX_DRIVE(sw);

		if (d == SP_DRIVE_FAULT || d == SP_DRIVE_FAULT_REACTION || d == SP_DRIVE_OFFLINE) {
			atomic_store(&pr->drive_fault, (int)((i << 16) | SP_AX_ERROR(sw)));
			lose_servo(pr, m, 4);
			return;
		}
	}
	if (p->resync && nfb == n) {	/* a hold position for every axis driven */
		for (uint32_t i = 0; i < n; i++)
			p->hold_pos[i] = fb->axis[i].actual_pos;
		p->have_hold = 1;
		p->resync = 0;
	}
	path_error_feedback(&p->pe, fb, nfb);
}

/* ---- control thread -------------------------------------------------------------- */

static int running(int m)
{
	return m == PM_ARMED || m == PM_RUN || m == PM_STOPPING;
}

/* Leave the sine: hold where the axes are commanded now (the cycle thread
 * takes the hold at its next cycle). */
static int leave_sine(struct prog_runner *pr, char *msg, size_t n)
{
	atomic_store(&pr->req_hold, 1);
	for (int i = 0; i < 50 && atomic_load(&pr->mode) == PM_SINE; i++) {
		struct timespec ts = { 0, 10000000 };

		nanosleep(&ts, 0);
	}
	if (atomic_load(&pr->mode) == PM_SINE) {
		atomic_store(&pr->req_hold, 0);
		snprintf(msg, n, "the cycle is not running (servo not attached?)");
		return SE_OFFLINE;
	}
	return SE_OK;
}

/* Reset the run's figures and arm it (under the cycle lock; the queue is
 * not in use in HOLD). */
static void arm_run(struct prog_runner *pr, const char *path, uint32_t period_us)
{
	struct prog_playback *p = &pr->play;

	memcpy(pr->run_start, p->hold_pos, sizeof(pr->run_start));
	pr->opt.period_us = period_us;
	p->armed_cycles = 0;
	path_error_reset(&p->pe);
	p->prog_cycles = p->underruns = p->setpoints_used = 0;
	p->line = 0;
	memset(&p->cur, 0, sizeof(p->cur));
	for (uint32_t i = 0; i < PROG_AXES; i++)
		p->cur.pos[i] = p->hold_pos[i];
	ring_reset(&pr->queue);
	atomic_store(&pr->req_stop, 0);
	atomic_store(&pr->feeder_done, 0);
	atomic_store(&pr->feeder_abort, 0);
	atomic_store(&pr->link_lost, 0);
	pthread_mutex_lock(&pr->info_lock);
	snprintf(pr->info.path, sizeof(pr->info.path), "%s", path);
	pr->info.error[0] = 0;
	pr->info.verdict = 0;
	memset(&pr->info.ms, 0, sizeof(pr->info.ms));
	pr->info.dry_setpoints = 0;
	pr->info.runs++;
	pthread_mutex_unlock(&pr->info_lock);
	atomic_store(&pr->result, PR_CHECKING);
	atomic_store(&pr->mode, PM_ARMED);
}

/* The program file, opened without waiting on it: a regular file only (a
 * FIFO would block the reader, a device could do anything on open), of at
 * most PROG_MAX_BYTES. SE_OK with *fdp, or SE_PROGRAM (msg). */
static int open_program(const char *path, int *fdp, char *msg, size_t n)
{
	struct stat st;
	int fd;

	if (stat(path, &st)) {
		snprintf(msg, n, "%s: %s", path, strerror(errno));
		return SE_PROGRAM;
	}
	if (!S_ISREG(st.st_mode)) {
		snprintf(msg, n, "%s: not a regular file (FIFOs, devices, sockets and directories are refused)",
			 path);
		return SE_PROGRAM;
	}
	fd = open(path, O_RDONLY | O_NONBLOCK | O_NOCTTY | O_CLOEXEC);
	if (fd < 0) {
		snprintf(msg, n, "%s: %s", path, strerror(errno));
		return SE_PROGRAM;
	}
	if (fstat(fd, &st) || !S_ISREG(st.st_mode) || st.st_size > (off_t)PROG_MAX_BYTES) {
		if (S_ISREG(st.st_mode))
			snprintf(msg, n, "%s: %lld bytes, more than the %u servod takes", path,
				 (long long)st.st_size, PROG_MAX_BYTES);
		else
			snprintf(msg, n, "%s: not a regular file (replaced while opened?)", path);
		close(fd);
		return SE_PROGRAM;
	}
	*fdp = fd;
	return SE_OK;
}

/* The previous run's feeder: told to end, joined if it has (it checks the
 * abort flag every few hundred setpoints); SE_BUSY if it has not within
 * 200 ms, rather than waiting on it. */
static int join_feeder(struct prog_runner *pr, char *msg, size_t n)
{
	struct timespec t;

	if (!pr->feeder_alive)
		return SE_OK;
	atomic_store(&pr->feeder_abort, 1);
	clock_gettime(CLOCK_REALTIME, &t);
	t.tv_nsec += 200000000;
	if (t.tv_nsec >= 1000000000) {
		t.tv_sec++;
		t.tv_nsec -= 1000000000;
	}
	if (pthread_timedjoin_np(pr->feeder_th, 0, &t)) {
		snprintf(msg, n, "the previous program's feeder has not ended yet: try again");
		return SE_BUSY;
	}
	pr->feeder_alive = 0;
	return SE_OK;
}

int prog_run(struct prog_runner *pr, const char *path, uint32_t period_us, char *msg, size_t n)
{
	int m = atomic_load(&pr->mode), rc, fd = -1;

	if (running(m)) {
		snprintf(msg, n, "a program is running (%s): ampctl stop first", pr->info.path);
		return SE_BUSY;
	}
	if (strlen(path) >= sizeof(pr->info.path)) {
		snprintf(msg, n, "path too long");
		return SE_USAGE;
	}
	rc = join_feeder(pr, msg, n);
	if (rc)
		return rc;
	rc = open_program(path, &fd, msg, n);
	if (rc)
		return rc;
	if (m == PM_SINE) {
		rc = leave_sine(pr, msg, n);
		if (rc) {
			close(fd);
			return rc;
		}
	}
	pthread_mutex_lock(pr->cycle_lock);
	if (!pr->play.have_hold) {
		pthread_mutex_unlock(pr->cycle_lock);
		close(fd);
		snprintf(msg, n, "no feedback yet: the hold position is unknown (servo not attached?)");
		return SE_OFFLINE;
	}
	arm_run(pr, path, period_us);
	pthread_mutex_unlock(pr->cycle_lock);

	pr->prog_fd = fd;
	rc = prog_feeder_start(pr);
	if (rc) {
		close(fd);
		pthread_mutex_lock(pr->cycle_lock);
		prog_end_run(pr, PR_FAULT);
		pthread_mutex_unlock(pr->cycle_lock);
		snprintf(msg, n, "feeder thread: %s", strerror(rc));
		return SE_IO;
	}
	pr->feeder_alive = 1;
	return SE_OK;
}

int prog_verdict(struct prog_runner *pr, int *refused, char *msg, size_t n)
{
	const struct prog_info *in = &pr->info;
	double k = pr->opt.inc_per_mm;
	int v;

	pthread_mutex_lock(&pr->info_lock);
	v = in->verdict;
	if (v == 2)
		snprintf(msg, n, "%s", in->error);
	else if (v == 1)
		snprintf(msg, n, "%s: checked (%llu setpoints = %.3f s, end X%.4f Y%.4f Z%.4f mm, "
			 "dry run %.2f s); running",
			 in->path, (unsigned long long)in->dry_setpoints,
			 (double)in->dry_setpoints * pr->opt.period_us * 1e-6, in->end_inc[0] / k,
			 in->end_inc[1] / k, in->end_inc[2] / k, in->t_check_s);
	pthread_mutex_unlock(&pr->info_lock);
	*refused = v == 2;
	return v != 0;
}

int prog_stop(struct prog_runner *pr, char *msg, size_t n)
{
	int m = atomic_load(&pr->mode);

	if (!running(m)) {
		snprintf(msg, n, "no program running (%s)", mode_name[m]);
		return SE_OK;
	}
	atomic_store(&pr->req_stop, 1);
	for (int i = 0; i < 300; i++) {	/* the ramp at amax takes a few cycles */
		struct timespec ts = { 0, 10000000 };

		m = atomic_load(&pr->mode);
		if (m == PM_HOLD)
			break;
		nanosleep(&ts, 0);
	}
	snprintf(msg, n, "%s", m == PM_HOLD ? "stopped, holding" : "stopping");
	return SE_OK;
}

/* ---- status and figures ------------------------------------------------------------ */

struct snap {
	int mode, result, link_lost, drive_fault;
	struct prog_playback play;
};

static void snapshot(struct prog_runner *pr, struct snap *s)
{
	pthread_mutex_lock(pr->cycle_lock);
	s->play = pr->play;
	s->mode = atomic_load(&pr->mode);
	s->result = atomic_load(&pr->result);
	s->link_lost = atomic_load(&pr->link_lost);
	s->drive_fault = atomic_load(&pr->drive_fault);
	pthread_mutex_unlock(pr->cycle_lock);
}

void prog_format_status(struct prog_runner *pr, struct out *o, const int32_t *cmd, const int32_t *act)
{
	const struct prog_info *in = &pr->info;
	struct snap s;

	snapshot(pr, &s);
	pthread_mutex_lock(&pr->info_lock);
	put(o, "program.mode=%s\nprogram.state=%s\n", mode_name[s.mode], result_name[s.result]);
	if (in->runs) {
		put(o, "program.file=%s\nprogram.line=%u\n", in->path, s.play.line);
		put(o, "program.lines=%llu\nprogram.blocks=%llu\nprogram.segments=%llu\nprogram.setpoints=%llu\n",
		    (unsigned long long)in->ms.lines, (unsigned long long)in->ms.blocks,
		    (unsigned long long)in->ms.segments, (unsigned long long)s.play.setpoints_used);
		put(o, "program.planned_setpoints=%llu\nprogram.underruns=%llu\nprogram.cycles=%llu\n",
		    (unsigned long long)in->dry_setpoints, (unsigned long long)s.play.underruns,
		    (unsigned long long)s.play.prog_cycles);
		put(o, "program.xoff=%llu\nprogram.xon=%llu\n", (unsigned long long)in->ms.xoff_events,
		    (unsigned long long)in->ms.xon_events);
		if (in->verdict == 1)
			put(o, "program.end_inc=%d,%d,%d\n", in->end_inc[0], in->end_inc[1], in->end_inc[2]);
		if (in->error[0])
			put(o, "program.error=%s\n", in->error);
		else if (s.link_lost == 4)
			put(o, "program.error=axis %d drive fault 0x%04x\n", s.drive_fault >> 16,
			    s.drive_fault & 0xffff);
		else if (s.link_lost)
			put(o, "program.error=%s\n", s.link_lost == 1 ? "servo link lost" :
			    s.link_lost == 3 ? "servo fault" : "servo in safe stop");
	}
	pthread_mutex_unlock(&pr->info_lock);
	put(o, "program.cmd_inc=%d,%d,%d\nprogram.act_inc=%d,%d,%d\n", cmd[0], cmd[1], cmd[2], act[0], act[1],
	    act[2]);
	put(o, "program.scale_inc_per_mm=%g\n", pr->opt.inc_per_mm);
}

void prog_format_stats(struct prog_runner *pr, struct out *o)
{
	struct snap s;

	snapshot(pr, &s);
	put(o, "motion.state=%s\n", result_name[s.result]);
	path_error_format(&s.play.pe, o, pr->opt.inc_per_mm);
	put(o, "motion.underruns=%llu\n", (unsigned long long)s.play.underruns);
}

/* ---- "run FILE" and "stop" ---------------------------------------------------------- */

/* Starts the run, then waits for the verdict of the dry run (whole program
 * checked before any motion) up to 5 s, keeping the supervisor going
 * meanwhile. */
static int req_run(struct servod *sd, struct out *o, int argc, char **argv, char *msg, size_t n)
{
	int rc, refused = 0;

	if (argc != 2) {
		snprintf(msg, n, "usage: run FILE");
		return SE_USAGE;
	}
	rc = prog_run(&sd->prog, argv[1], sd->pset[SP_P_cycle_period_us], msg, n);
	if (rc)
		return rc;
	logm(sd, "program %s: checking", argv[1]);
	for (int i = 0; i < 250; i++) {
		struct timespec ts = { 0, 20000000 };

		if (prog_verdict(&sd->prog, &refused, msg, n)) {
			if (refused) {
				logm(sd, "program refused: %s", msg);
				return SE_PROGRAM;
			}
			logm(sd, "program %s", msg);
			put(o, "%s\n", msg);
			return SE_OK;
		}
		supervise(sd);
		nanosleep(&ts, 0);
	}
	put(o, "%s: still checking (ampctl status shows the verdict)\n", argv[1]);
	return SE_OK;
}
SERVOD_REQUEST("run", req_run);

static int req_stop(struct servod *sd, struct out *o, int argc, char **argv, char *msg, size_t n)
{
	int rc = prog_stop(&sd->prog, msg, n);

	(void)argc, (void)argv;
	if (!rc)
		put(o, "%s\n", msg);
	return rc;
}
SERVOD_REQUEST("stop", req_stop);
