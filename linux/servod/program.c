// SPDX-License-Identifier: MIT
/*
 * program.c - servod's G-code runner (program.h, docs/cycle.md).
 *
 * Pipeline axes X, Y, Z drive servo axes 0, 1, 2 (as many as the servo
 * has); the other servo axes hold the position they had when the run
 * started. Scale: opt.inc_per_mm servo increments per program millimetre
 * (the pipeline's increments_per_mm), default 1000: 1 increment = 1 um.
 *
 * Modes of the cycle thread (mode):
 *   SINE      servod's idle sine (before the first run, unless --idle hold)
 *   HOLD      hold hold_pos[] (after a run, a stop, a refused program)
 *   ARMED     hold, until the axes settled (SETTLE_CYCLES) and the ring is
 *             primed (PREFILL setpoints or the whole program), then RUN
 *   RUN       one setpoint popped per cycle
 *   STOPPING  `ampctl stop`: the program's own path, time-scaled by a speed
 *             factor that ramps 1 -> 0 at opt.amax, then HOLD
 *
 * Path error (per cycle, on every new feedback record): the feedback names
 * the command sequence the servo consumed (fb.cmd_seq) and its actual
 * position is the plant's state when its fine interpolation reached that
 * coarse setpoint, so the commanded point to compare with is the one of
 * that sequence (hist[]): no guessed delay.
 *   following error (XY) = |commanded(cmd_seq) - actual|
 *   path (contour) error = distance from the actual point to the commanded
 *                          polyline (the last HIST_BACK setpoints up to the
 *                          newest one), i.e. the deviation across the path
 * Both in increments, reported in um too.
 */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "motion/motion.h"
#include "program.h"
#include "servoamp/servo_proto.h"
#include "servod.h"

#define RING_N 1024u		/* setpoints buffered ahead (1.02 s at 1 ms) */
#define PREFILL 256u		/* setpoints ready before the run starts */
#define SETTLE_CYCLES 200u	/* hold before the run starts (axes settle from the sine) */
#define HIST_N 64u		/* commanded points kept by command sequence */
#define HIST_BACK 24u		/* contour error: polyline segments looked at */
#define PAXES 3u		/* X Y Z */

enum mode { M_SINE, M_HOLD, M_ARMED, M_RUN, M_STOPPING };
enum result { R_NONE, R_CHECKING, R_RUNNING, R_DONE, R_STOPPED, R_FAULT, R_REFUSED };
static const char *const mode_name[] = { "sine", "hold", "armed", "run", "stopping" };
static const char *const result_name[] = { "none", "checking", "running", "done", "stopped",
					   "fault", "refused" };

static struct prog_opts opt;
static pthread_mutex_t *cycle_lock;

/* ---- the setpoint ring: feeder (producer) -> cycle thread (consumer) ------ */
static struct motion_setpoint ring[RING_N];
static _Atomic uint32_t ring_head, ring_tail;	/* head: consumer, tail: producer */

static uint32_t ring_count(void)
{
	return atomic_load_explicit(&ring_tail, memory_order_acquire) -
	       atomic_load_explicit(&ring_head, memory_order_acquire);
}

static const struct motion_setpoint *ring_peek(void)
{
	uint32_t h = atomic_load_explicit(&ring_head, memory_order_relaxed);

	if (atomic_load_explicit(&ring_tail, memory_order_acquire) == h)
		return 0;
	return &ring[h % RING_N];
}

static void ring_drop(void)
{
	atomic_store_explicit(&ring_head, atomic_load_explicit(&ring_head, memory_order_relaxed) + 1u,
			      memory_order_release);
}

static void ring_push(const struct motion_setpoint *sp)	/* caller checked the room */
{
	uint32_t t = atomic_load_explicit(&ring_tail, memory_order_relaxed);

	ring[t % RING_N] = *sp;
	atomic_store_explicit(&ring_tail, t + 1u, memory_order_release);
}

/* ---- state shared with the cycle thread ---------------------------------------- */
static _Atomic int mode = M_SINE;
static _Atomic int result = R_NONE;
static atomic_int req_hold, req_stop, feeder_done, feeder_abort, link_lost;

/* Written by the cycle thread (under cycle_lock). */
static struct {
	int32_t hold_pos[AMP_MAX_AXES];
	int have_hold;
	int resync;			/* the next feedback sets hold_pos (start, servo restarted) */
	uint32_t armed_cycles;
	struct motion_setpoint cur;	/* last setpoint sent in RUN / STOPPING */
	double stop_s, stop_ds, stop_f;	/* stop: speed factor, its step, fraction cur -> next */
	uint32_t line;			/* source line of the last setpoint */
	uint64_t prog_cycles, underruns, setpoints_used;
	int32_t cmd[AMP_MAX_AXES], act[AMP_MAX_AXES];
	/* path error */
	uint32_t seq_first, seq_last;	/* command sequences of the program (last: 0 = open) */
	int measuring;
	uint64_t samples, align_mismatch, cmd_skips;
	uint32_t last_fb_seq;
	double pe_max, pe_sq, fe_max, fe_sq;	/* increments */
	uint32_t pe_max_line, fe_max_line;
	int32_t pe_max_at[2];
	int32_t axis_fe_max[PAXES];
} c;

struct hist_pt {
	uint32_t seq, line;
	int32_t x, y;
};
static struct hist_pt hist[HIST_N];
static uint32_t hist_newest;

/* Written by the control / feeder threads (under info_lock). */
static pthread_mutex_t info_lock = PTHREAD_MUTEX_INITIALIZER;
static struct {
	char path[256];
	char error[512];
	int verdict;			/* 0 checking, 1 ok, 2 refused */
	struct motion_stats ms;		/* of the running pipeline (feeder's snapshot) */
	uint64_t dry_setpoints;
	int32_t end_inc[PAXES];		/* program end point (dry run), increments */
	double t_check_s;
	uint64_t runs;
} info;

static pthread_t feeder_th;
static int feeder_alive;

void prog_init(const struct prog_opts *o, pthread_mutex_t *lock)
{
	opt = *o;
	cycle_lock = lock;
	atomic_store(&mode, o->idle_hold ? M_HOLD : M_SINE);
	c.resync = o->idle_hold;
}

/* ---- cycle thread --------------------------------------------------------------- */

static void end_run(int res)
{
	atomic_store(&result, res);
	atomic_store(&mode, M_HOLD);
	c.seq_last = hist_newest;
	atomic_store(&feeder_abort, 1);
}

static void set_prog_cmd(struct amp_cmd_axis *cmd, uint32_t n, const int32_t *pos, const int32_t *vel)
{
	for (uint32_t i = 0; i < n && i < PAXES; i++) {
		c.hold_pos[i] = pos[i];
		cmd[i].target_pos = pos[i];
		cmd[i].vel_ff = vel ? vel[i] : 0;
	}
}

void prog_cycle(struct amp_cmd_axis *cmd, uint32_t n, uint32_t seq)
{
	int m = atomic_load_explicit(&mode, memory_order_acquire);
	const struct motion_setpoint *sp;

	if (m == M_SINE && atomic_load(&req_hold)) {
		for (uint32_t i = 0; i < n; i++)
			c.hold_pos[i] = cmd[i].target_pos;
		c.have_hold = 1;
		m = M_HOLD;
		atomic_store(&mode, m);
		atomic_store(&req_hold, 0);
	}
	if (m == M_ARMED) {
		if (atomic_load(&req_stop)) {
			end_run(R_STOPPED);
			m = M_HOLD;
		} else if (++c.armed_cycles >= SETTLE_CYCLES &&
			   (ring_count() >= PREFILL || atomic_load(&feeder_done))) {
			m = M_RUN;
			c.seq_first = seq;
			c.seq_last = 0;
			c.measuring = 1;
			atomic_store(&mode, m);
		}
	}
	if (m == M_RUN && atomic_load(&req_stop)) {
		double v2 = 0;

		for (uint32_t i = 0; i < PAXES; i++)
			v2 += (double)c.cur.vel[i] * (double)c.cur.vel[i];
		/* speed factor 1 -> 0 in N cycles: N = v / (amax T) */
		double ncyc = ceil(sqrt(v2) / (opt.amax * opt.inc_per_mm * opt.period_us * 1e-6));
		c.stop_ds = 1.0 / (ncyc < 1.0 ? 1.0 : ncyc);
		c.stop_s = 1.0;
		c.stop_f = 0.0;
		m = M_STOPPING;
		atomic_store(&mode, m);
	}
	if (m == M_RUN) {
		c.prog_cycles++;
		sp = ring_peek();
		if (!sp) {
			c.underruns++;	/* hold the last setpoint for this cycle */
			set_prog_cmd(cmd, n, c.cur.pos, 0);
		} else {
			c.cur = *sp;
			ring_drop();
			c.setpoints_used++;
			c.line = c.cur.line;
			set_prog_cmd(cmd, n, c.cur.pos, c.cur.vel);
			if (c.cur.status == MOTION_ST_DONE)
				end_run(R_DONE);
			else if (c.cur.status == MOTION_ST_FAULT || c.cur.status == MOTION_ST_UNDERRUN)
				end_run(R_FAULT);
		}
	} else if (m == M_STOPPING) {
		/* the program's own path, time-scaled: the position advances by
		 * stop_s setpoints per cycle, interpolated between cur and the next */
		const struct motion_setpoint *nx;
		int32_t pos[PAXES];

		c.prog_cycles++;
		c.stop_s -= c.stop_ds;
		if (c.stop_s < 1e-9)
			c.stop_s = 0.0;
		c.stop_f += c.stop_s;
		while (c.stop_f >= 1.0) {
			nx = ring_peek();
			if (!nx || nx->status != MOTION_ST_MOVING) {
				c.stop_f = 0.0;
				break;
			}
			c.cur = *nx;
			ring_drop();
			c.stop_f -= 1.0;
		}
		nx = ring_peek();
		for (uint32_t i = 0; i < PAXES; i++) {
			double b = (nx && nx->status == MOTION_ST_MOVING) ? nx->pos[i] : c.cur.pos[i];

			pos[i] = (int32_t)lround(c.cur.pos[i] + c.stop_f * (b - c.cur.pos[i]));
		}
		c.line = c.cur.line;
		set_prog_cmd(cmd, n, pos, 0);
		if (c.stop_s == 0.0)
			end_run(R_STOPPED);
	} else if (m != M_SINE) {
		for (uint32_t i = 0; i < n; i++) {
			cmd[i].target_pos = c.hold_pos[i];
			cmd[i].vel_ff = 0;
		}
	}
	if (m != M_SINE)	/* axes beyond Z: the position they had */
		for (uint32_t i = PAXES; i < n; i++)
			cmd[i].target_pos = c.hold_pos[i], cmd[i].vel_ff = 0;
	if (m != M_SINE && !c.have_hold)	/* position unknown (start, servo restart): */
		for (uint32_t i = 0; i < n; i++)	/* axes disabled until the next feedback */
			cmd[i].control_word = 0;
	for (uint32_t i = 0; i < n && i < AMP_MAX_AXES; i++)
		c.cmd[i] = cmd[i].target_pos;
	{
		struct hist_pt *h = &hist[seq % HIST_N];

		h->seq = seq;
		h->line = c.line;
		h->x = n > 0 ? cmd[0].target_pos : 0;
		h->y = n > 1 ? cmd[1].target_pos : 0;
		hist_newest = seq;
	}
}

static double seg_dist(double px, double py, const struct hist_pt *a, const struct hist_pt *b)
{
	double dx = (double)b->x - a->x, dy = (double)b->y - a->y;
	double l2 = dx * dx + dy * dy, t = 0.0;

	if (l2 > 0.0) {
		t = ((px - a->x) * dx + (py - a->y) * dy) / l2;
		t = t < 0.0 ? 0.0 : t > 1.0 ? 1.0 : t;
	}
	dx = a->x + t * dx - px;
	dy = a->y + t * dy - py;
	return sqrt(dx * dx + dy * dy);
}

/* The servo cannot follow (why: 1 link lost, 2 safe stop): a running
 * program ends in fault and the hold position is resynchronised from the
 * next fresh feedback. */
static void lose_servo(int m, int why)
{
	if (m == M_ARMED || m == M_RUN || m == M_STOPPING) {
		atomic_store(&link_lost, why);
		end_run(R_FAULT);
	}
	if (m != M_SINE) {
		c.resync = 1;
		c.have_hold = 0;
	}
}

void prog_feedback(int rc, const struct amp_fb_record *fb, uint32_t n, int fresh)
{
	int m = atomic_load_explicit(&mode, memory_order_relaxed);
	uint32_t s;

	if (rc != AMP_OK) {
		/* servo gone, stalled or restarting: a running program ends
		 * and the next feedback resynchronises the hold position */
		if (rc != AMP_E_PEER_ERROR)
			lose_servo(m, 1);
		return;
	}
	if (!fresh)
		return;
	for (uint32_t i = 0; i < n && i < AMP_MAX_AXES; i++)
		c.act[i] = fb->axis[i].actual_pos;
	if (n && (fb->axis[0].status_word & SP_AX_SAFESTOP)) {
		lose_servo(m, 2);
		return;
	}
	if (c.resync) {
		for (uint32_t i = 0; i < n && i < AMP_MAX_AXES; i++)
			c.hold_pos[i] = fb->axis[i].actual_pos;
		c.have_hold = 1;
		c.resync = 0;
	}
	if (!c.measuring || n < 2)
		return;
	s = fb->cmd_seq;
	if ((int32_t)(s - c.seq_first) < 0)
		return;
	if (c.seq_last && (int32_t)(s - c.seq_last) > 0) {
		c.measuring = 0;	/* past the program's last command */
		return;
	}
	if (c.samples && s - c.last_fb_seq > 1u)
		c.cmd_skips += s - c.last_fb_seq - 1u;
	c.last_fb_seq = s;
	{
		const struct hist_pt *h = &hist[s % HIST_N];
		double px = fb->axis[0].actual_pos, py = fb->axis[1].actual_pos, fe, pe = INFINITY;
		double fex = fb->axis[0].following_error, fey = fb->axis[1].following_error;

		if (h->seq != s || hist_newest - s >= HIST_N - 1u)
			return;	/* too old (should not happen: the servo is <= 2 cycles behind) */
		fe = hypot(px - h->x, py - h->y);
		/* the servo's own following error is p1 - actual: the same if aligned */
		if (fabs(hypot(fex, fey) - fe) > 1.5)
			c.align_mismatch++;
		for (uint32_t k = 1; k <= HIST_BACK && k < HIST_N - 1u; k++) {
			uint32_t j = hist_newest - k;
			const struct hist_pt *a = &hist[j % HIST_N], *b = &hist[(j + 1u) % HIST_N];
			double d;

			if (a->seq != j || b->seq != j + 1u)
				break;
			d = seg_dist(px, py, a, b);
			if (d < pe)
				pe = d;
			if ((int32_t)(j - s) < -8)
				break;	/* far enough behind the aligned point */
		}
		if (!isfinite(pe))
			pe = fe;
		c.samples++;
		c.fe_sq += fe * fe;
		c.pe_sq += pe * pe;
		if (fe > c.fe_max) {
			c.fe_max = fe;
			c.fe_max_line = h->line;
		}
		if (pe > c.pe_max) {
			c.pe_max = pe;
			c.pe_max_line = h->line;
			c.pe_max_at[0] = (int32_t)px;
			c.pe_max_at[1] = (int32_t)py;
		}
		for (uint32_t i = 0; i < PAXES && i < n; i++) {
			int32_t e = fb->axis[i].following_error;

			e = e < 0 ? -e : e;
			if (e > c.axis_fe_max[i])
				c.axis_fe_max[i] = e;
		}
	}
}

/* ---- feeder thread ------------------------------------------------------------ */

static void motion_cfg(struct motion_config *cfg, const int32_t *start)
{
	motion_config_default(cfg);
	cfg->n_axes = PAXES;
	cfg->period_us = opt.period_us;
	cfg->increments_per_mm = opt.inc_per_mm;
	for (uint32_t k = 0; k < PAXES; k++) {
		cfg->axis[k].vmax = opt.vmax;
		cfg->axis[k].amax = opt.amax;
		cfg->axis[k].min = -opt.travel;
		cfg->axis[k].max = opt.travel;
		cfg->start_pos[k] = start ? start[k] / opt.inc_per_mm : 0.0;
	}
}

static uint64_t now_ns(void)
{
	struct timespec ts;

	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (uint64_t)ts.tv_sec * 1000000000ull + (uint64_t)ts.tv_nsec;
}

struct sink {
	int to_ring;		/* 0: dry run (count, keep the last) */
	uint64_t n;
	struct motion_setpoint last;
};

/* Streams the file into m with the pipeline's flow control and takes its
 * setpoints until DONE / FAULT. Returns the final status, or -1 (aborted
 * or I/O error: msg). */
static int stream_program(struct motion *m, const char *path, struct sink *k, char *msg, size_t msgn)
{
	static char buf[4096];	/* the feeder is the only user */
	size_t have = 0, off = 0;
	int fd = open(path, O_RDONLY | O_CLOEXEC), ended = 0;
	uint32_t batches = 0;

	if (fd < 0) {
		snprintf(msg, msgn, "%s: %s", path, strerror(errno));
		return -1;
	}
	for (;;) {
		uint32_t room;

		if (atomic_load(&feeder_abort)) {
			close(fd);
			snprintf(msg, msgn, "aborted");
			return -1;
		}
		/* input: write while the pipeline says XON (it raises XOFF at
		 * stream_high and XON again once drained to stream_low) */
		while (!ended && motion_stream_flow(m) == MOTION_FLOW_XON) {
			long w;

			if (off == have) {
				ssize_t r = read(fd, buf, sizeof(buf));

				if (r < 0) {
					snprintf(msg, msgn, "%s: read: %s", path, strerror(errno));
					close(fd);
					return -1;
				}
				if (r == 0) {
					motion_stream_end(m);
					ended = 1;
					break;
				}
				have = (size_t)r;
				off = 0;
			}
			w = motion_stream_write(m, buf + off, have - off);
			if (w < 0) {	/* the pipeline faulted: it takes no more input */
				ended = 1;
				break;
			}
			off += (size_t)w;
			if (w == 0)
				break;
		}
		/* output */
		room = k->to_ring ? RING_N - ring_count() : 512u;
		if (!room) {
			struct timespec ts = { 0, 2000000 };

			nanosleep(&ts, 0);
			continue;
		}
		while (room--) {
			struct motion_setpoint sp;
			enum motion_status st = motion_next_setpoint(m, &sp);

			if (k->to_ring)
				ring_push(&sp);
			k->last = sp;
			k->n++;
			if (st == MOTION_ST_DONE || st == MOTION_ST_FAULT || st == MOTION_ST_UNDERRUN) {
				close(fd);
				return st;
			}
			if (!ended && motion_stream_flow(m) == MOTION_FLOW_XON)
				break;	/* drained to the low watermark: refill first */
		}
		if (k->to_ring && (++batches & 7u) == 0) {
			pthread_mutex_lock(&info_lock);
			motion_get_stats(m, &info.ms);
			pthread_mutex_unlock(&info_lock);
		}
	}
}

static void fmt_error(const struct motion_error *e, const char *path, char *buf, size_t n)
{
	if (!e)
		snprintf(buf, n, "%s: error: unknown", path);
	else if (e->line)
		snprintf(buf, n, "%s:%u:%u: error: %s (%s)", path, e->line, e->column, e->msg,
			 motion_errcode_name(e->code));
	else
		snprintf(buf, n, "%s: error: %s (%s)", path, e->msg, motion_errcode_name(e->code));
}

static void *feeder_main(void *arg)
{
	int32_t *start = arg;
	struct motion_config cfg;
	struct motion_error err;
	struct motion *m = 0;
	struct sink k;
	char msg[512] = "";
	int st;
	uint64_t t0 = now_ns();

	/* 1. dry run: the whole program through a second pipeline instance,
	 * synchronous, nothing sent to the servo */
	motion_cfg(&cfg, start);
	if (motion_create(&cfg, &m, &err)) {
		fmt_error(&err, "config", msg, sizeof(msg));
		goto refused;
	}
	memset(&k, 0, sizeof(k));
	st = stream_program(m, info.path, &k, msg, sizeof(msg));
	if (st == MOTION_ST_FAULT || st == MOTION_ST_UNDERRUN)
		fmt_error(motion_last_error(m), info.path, msg, sizeof(msg));
	motion_destroy(m);
	m = 0;
	if (st != MOTION_ST_DONE)
		goto refused;
	pthread_mutex_lock(&info_lock);
	info.dry_setpoints = k.n;
	for (uint32_t i = 0; i < PAXES; i++)
		info.end_inc[i] = k.last.pos[i];
	info.t_check_s = (double)(now_ns() - t0) * 1e-9;
	info.verdict = 1;
	pthread_mutex_unlock(&info_lock);
	{
		int want = R_CHECKING;

		atomic_compare_exchange_strong(&result, &want, R_RUNNING);
	}

	/* 2. the run: the cycle thread is ARMED and pops the ring */
	if (motion_create(&cfg, &m, &err)) {
		fmt_error(&err, "config", msg, sizeof(msg));
		goto fault;
	}
	memset(&k, 0, sizeof(k));
	k.to_ring = 1;
	st = stream_program(m, info.path, &k, msg, sizeof(msg));
	pthread_mutex_lock(&info_lock);
	motion_get_stats(m, &info.ms);
	if (st == MOTION_ST_FAULT || st == MOTION_ST_UNDERRUN)
		fmt_error(motion_last_error(m), info.path, info.error, sizeof(info.error));
	else if (st < 0 && !atomic_load(&feeder_abort))
		snprintf(info.error, sizeof(info.error), "%s", msg);
	pthread_mutex_unlock(&info_lock);
	motion_destroy(m);
	if (st < 0 && !atomic_load(&feeder_abort))
		goto fault_marker;
	atomic_store(&feeder_done, 1);
	return 0;

fault:
	pthread_mutex_lock(&info_lock);
	snprintf(info.error, sizeof(info.error), "%s", msg);
	pthread_mutex_unlock(&info_lock);
fault_marker:
	/* the cycle thread ends the run on a FAULT setpoint at the last position */
	while (RING_N - ring_count() == 0 && !atomic_load(&feeder_abort)) {
		struct timespec ts = { 0, 2000000 };

		nanosleep(&ts, 0);
	}
	if (!atomic_load(&feeder_abort)) {
		k.last.status = MOTION_ST_FAULT;
		memset(k.last.vel, 0, sizeof(k.last.vel));
		if (!k.n)
			for (uint32_t i = 0; i < PAXES; i++)
				k.last.pos[i] = start[i];
		ring_push(&k.last);
	}
	atomic_store(&feeder_done, 1);
	return 0;

refused:
	pthread_mutex_lock(&info_lock);
	snprintf(info.error, sizeof(info.error), "%s", msg);
	info.verdict = 2;
	info.t_check_s = (double)(now_ns() - t0) * 1e-9;
	pthread_mutex_unlock(&info_lock);
	pthread_mutex_lock(cycle_lock);
	if (atomic_load(&mode) == M_ARMED)
		end_run(R_REFUSED);
	pthread_mutex_unlock(cycle_lock);
	atomic_store(&feeder_done, 1);
	return 0;
}

/* ---- control thread -------------------------------------------------------------- */

static int32_t run_start[AMP_MAX_AXES];

int prog_run(const char *path, uint32_t period_us, char *msg, size_t n)
{
	int m = atomic_load(&mode);
	pthread_attr_t attr;
	int rc;

	if (m == M_ARMED || m == M_RUN || m == M_STOPPING) {
		snprintf(msg, n, "a program is running (%s): ampctl stop first", info.path);
		return SE_BUSY;
	}
	if (strlen(path) >= sizeof(info.path)) {
		snprintf(msg, n, "path too long");
		return SE_USAGE;
	}
	if (access(path, R_OK)) {
		snprintf(msg, n, "%s: %s", path, strerror(errno));
		return SE_PROGRAM;
	}
	if (feeder_alive) {
		atomic_store(&feeder_abort, 1);
		pthread_join(feeder_th, 0);
		feeder_alive = 0;
	}
	/* leave the sine: hold where the axes are commanded now */
	if (m == M_SINE) {
		atomic_store(&req_hold, 1);
		for (int i = 0; i < 50 && atomic_load(&mode) == M_SINE; i++) {
			struct timespec ts = { 0, 10000000 };

			nanosleep(&ts, 0);
		}
		if (atomic_load(&mode) == M_SINE) {
			atomic_store(&req_hold, 0);
			snprintf(msg, n, "the cycle is not running (servo not attached?)");
			return SE_OFFLINE;
		}
	}
	pthread_mutex_lock(cycle_lock);
	if (!c.have_hold) {
		pthread_mutex_unlock(cycle_lock);
		snprintf(msg, n, "no feedback yet: the hold position is unknown (servo not attached?)");
		return SE_OFFLINE;
	}
	memcpy(run_start, c.hold_pos, sizeof(run_start));
	opt.period_us = period_us;
	/* reset the run's figures; the ring is not in use in HOLD */
	c.armed_cycles = 0;
	c.measuring = 0;
	c.seq_first = c.seq_last = 0;
	c.samples = c.align_mismatch = c.cmd_skips = 0;
	c.pe_max = c.pe_sq = c.fe_max = c.fe_sq = 0.0;
	c.pe_max_line = c.fe_max_line = 0;
	memset(c.pe_max_at, 0, sizeof(c.pe_max_at));
	memset(c.axis_fe_max, 0, sizeof(c.axis_fe_max));
	c.prog_cycles = c.underruns = c.setpoints_used = 0;
	c.line = 0;
	memset(&c.cur, 0, sizeof(c.cur));
	for (uint32_t i = 0; i < PAXES; i++)
		c.cur.pos[i] = c.hold_pos[i];
	atomic_store(&ring_head, 0);
	atomic_store(&ring_tail, 0);
	atomic_store(&req_stop, 0);
	atomic_store(&feeder_done, 0);
	atomic_store(&feeder_abort, 0);
	atomic_store(&link_lost, 0);
	pthread_mutex_lock(&info_lock);
	snprintf(info.path, sizeof(info.path), "%s", path);
	info.error[0] = 0;
	info.verdict = 0;
	memset(&info.ms, 0, sizeof(info.ms));
	info.dry_setpoints = 0;
	info.runs++;
	pthread_mutex_unlock(&info_lock);
	atomic_store(&result, R_CHECKING);
	atomic_store(&mode, M_ARMED);
	pthread_mutex_unlock(cycle_lock);

	pthread_attr_init(&attr);
	pthread_attr_setinheritsched(&attr, PTHREAD_EXPLICIT_SCHED);
	pthread_attr_setschedpolicy(&attr, SCHED_OTHER);
	rc = pthread_create(&feeder_th, &attr, feeder_main, run_start);
	pthread_attr_destroy(&attr);
	if (rc) {
		pthread_mutex_lock(cycle_lock);
		end_run(R_FAULT);
		pthread_mutex_unlock(cycle_lock);
		snprintf(msg, n, "feeder thread: %s", strerror(rc));
		return SE_IO;
	}
	feeder_alive = 1;
	return SE_OK;
}

int prog_verdict(int *refused, char *msg, size_t n)
{
	int v;

	pthread_mutex_lock(&info_lock);
	v = info.verdict;
	if (v == 2)
		snprintf(msg, n, "%s", info.error);
	else if (v == 1)
		snprintf(msg, n, "%s: checked (%llu setpoints = %.3f s, end X%.4f Y%.4f Z%.4f mm, "
			 "dry run %.2f s); running",
			 info.path, (unsigned long long)info.dry_setpoints,
			 (double)info.dry_setpoints * opt.period_us * 1e-6, info.end_inc[0] / opt.inc_per_mm,
			 info.end_inc[1] / opt.inc_per_mm, info.end_inc[2] / opt.inc_per_mm, info.t_check_s);
	pthread_mutex_unlock(&info_lock);
	*refused = v == 2;
	return v != 0;
}

int prog_stop(char *msg, size_t n)
{
	int m = atomic_load(&mode);

	if (m != M_ARMED && m != M_RUN && m != M_STOPPING) {
		snprintf(msg, n, "no program running (%s)", mode_name[m]);
		return SE_OK;
	}
	atomic_store(&req_stop, 1);
	for (int i = 0; i < 300; i++) {	/* the ramp at amax takes a few cycles */
		struct timespec ts = { 0, 10000000 };

		m = atomic_load(&mode);
		if (m == M_HOLD)
			break;
		nanosleep(&ts, 0);
	}
	snprintf(msg, n, "%s", m == M_HOLD ? "stopped, holding" : "stopping");
	return SE_OK;
}

static double um(double inc)
{
	return inc * 1000.0 / opt.inc_per_mm;
}

struct snap {
	int mode, result, link_lost;
	__typeof__(c) c;
};

static void snapshot(struct snap *s)
{
	pthread_mutex_lock(cycle_lock);
	s->c = c;
	s->mode = atomic_load(&mode);
	s->result = atomic_load(&result);
	s->link_lost = atomic_load(&link_lost);
	pthread_mutex_unlock(cycle_lock);
}

#define PUT(...) do { \
	if (len < n) { \
		int w_ = snprintf(buf + len, n - len, __VA_ARGS__); \
		if (w_ > 0) len += (size_t)w_; \
	} \
} while (0)

void prog_format_status(char *buf, size_t n)
{
	struct snap s;
	size_t len = 0;

	snapshot(&s);
	pthread_mutex_lock(&info_lock);
	PUT("program.mode=%s\nprogram.state=%s\n", mode_name[s.mode], result_name[s.result]);
	if (info.runs) {
		PUT("program.file=%s\nprogram.line=%u\n", info.path, s.c.line);
		PUT("program.lines=%llu\nprogram.blocks=%llu\nprogram.segments=%llu\nprogram.setpoints=%llu\n",
		    (unsigned long long)info.ms.lines, (unsigned long long)info.ms.blocks,
		    (unsigned long long)info.ms.segments, (unsigned long long)s.c.setpoints_used);
		PUT("program.planned_setpoints=%llu\nprogram.underruns=%llu\nprogram.cycles=%llu\n",
		    (unsigned long long)info.dry_setpoints, (unsigned long long)s.c.underruns,
		    (unsigned long long)s.c.prog_cycles);
		PUT("program.xoff=%llu\nprogram.xon=%llu\n", (unsigned long long)info.ms.xoff_events,
		    (unsigned long long)info.ms.xon_events);
		if (info.verdict == 1)
			PUT("program.end_inc=%d,%d,%d\n", info.end_inc[0], info.end_inc[1], info.end_inc[2]);
		if (info.error[0])
			PUT("program.error=%s\n", info.error);
		else if (s.link_lost)
			PUT("program.error=%s\n", s.link_lost == 1 ? "servo link lost" : "servo in safe stop");
	}
	pthread_mutex_unlock(&info_lock);
	PUT("program.cmd_inc=%d,%d,%d\nprogram.act_inc=%d,%d,%d\n", s.c.cmd[0], s.c.cmd[1], s.c.cmd[2],
	    s.c.act[0], s.c.act[1], s.c.act[2]);
	PUT("program.scale_inc_per_mm=%g\n", opt.inc_per_mm);
}

void prog_format_stats(char *buf, size_t n)
{
	struct snap s;
	size_t len = 0;
	double k;

	snapshot(&s);
	k = s.c.samples ? 1.0 / (double)s.c.samples : 0.0;
	PUT("motion.state=%s\nmotion.samples=%llu\n", result_name[s.result], (unsigned long long)s.c.samples);
	PUT("motion.path_err.max_um=%.1f\nmotion.path_err.rms_um=%.2f\nmotion.path_err.max_line=%u\n",
	    um(s.c.pe_max), um(sqrt(s.c.pe_sq * k)), s.c.pe_max_line);
	PUT("motion.path_err.max_at_inc=%d,%d\n", s.c.pe_max_at[0], s.c.pe_max_at[1]);
	PUT("motion.follow_err.max_um=%.1f\nmotion.follow_err.rms_um=%.2f\nmotion.follow_err.max_line=%u\n",
	    um(s.c.fe_max), um(sqrt(s.c.fe_sq * k)), s.c.fe_max_line);
	PUT("motion.follow_err.axis_max_inc=%d,%d,%d\n", s.c.axis_fe_max[0], s.c.axis_fe_max[1],
	    s.c.axis_fe_max[2]);
	PUT("motion.align_mismatch=%llu\nmotion.cmd_skips=%llu\nmotion.underruns=%llu\n",
	    (unsigned long long)s.c.align_mismatch, (unsigned long long)s.c.cmd_skips,
	    (unsigned long long)s.c.underruns);
}
