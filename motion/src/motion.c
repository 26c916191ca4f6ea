/* SPDX-License-Identifier: MIT */
/*
 * The pipeline: stream -> decode -> fit -> look-ahead -> accel -> interp ->
 * setpoints, each stage a data-dependent task of the hybrid scheduler.
 */
#define _POSIX_C_SOURCE 200809L
#include <math.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "internal.h"
#include "motion/gcode.h"
#include "motion/motion.h"
#include "motion/ring.h"
#include "motion/sched.h"

#define PI 3.14159265358979323846

enum { Q_STREAM, Q_BLOCKS, Q_SEGS, Q_PLANNED, Q_PROFILES, Q_SETPOINTS };
static const char *const queue_names[MOTION_N_QUEUES] = {
	"stream_bytes", "blocks", "segments", "planned", "profiles", "setpoints",
};

const char *motion_queue_name(unsigned q)
{
	return q < MOTION_N_QUEUES ? queue_names[q] : "?";
}

const char *motion_errcode_name(enum motion_errcode code)
{
	switch (code) {
	case MOTION_E_NONE: return "none";
	case MOTION_E_SYNTAX: return "syntax";
	case MOTION_E_NUMBER: return "number";
	case MOTION_E_UNSUPPORTED: return "unsupported";
	case MOTION_E_MODAL: return "modal";
	case MOTION_E_MISSING: return "missing";
	case MOTION_E_ARC: return "arc";
	case MOTION_E_TRAVEL: return "travel";
	case MOTION_E_LINE_TOO_LONG: return "line-too-long";
	case MOTION_E_CONFIG: return "config";
	case MOTION_E_NOMEM: return "nomem";
	case MOTION_E_STATE: return "state";
	case MOTION_E_UNDERRUN: return "underrun";
	}
	return "?";
}

/* A segment by its position in the segment ring (see struct seg). */
static inline const struct seg *seg_at(const struct motion *m, uint32_t pos);

/* ---- input: a byte stream with watermarks, or a program in memory ---- */

/* The writer's and the decoder's fields are on separate cache lines
 * (CL below), so a host thread writing the stream and a worker decoding it
 * do not bounce one line per line of G-code. */
#define CL 64

struct source {
	unsigned char *buf;
	uint32_t size, mask;
	uint32_t high, low;
	/* memory program (read-only after motion_load_program) */
	bool mem;
	const char *text;
	size_t text_len;
	uint32_t text_lines;
	/* writer side */
	_Alignas(CL) _Atomic uint32_t tail;   /* free-running byte index */
	_Atomic uint32_t lines_in;            /* newlines written */
	_Atomic uint32_t peak;
	atomic_bool eos;
	/* decoder side */
	_Alignas(CL) _Atomic uint32_t head;   /* free-running byte index */
	_Atomic uint32_t lines_out;           /* newlines consumed */
	_Atomic size_t text_pos;
	_Atomic uint32_t text_lines_out;
	/* flow control (both sides, only at the watermarks) */
	_Alignas(CL) pthread_mutex_t flow_lock;
	atomic_int flow;
	_Atomic uint32_t flow_lvl;	/* level at the latest XOFF/XON */
	_Atomic uint64_t xoff, xon;
};

/* Each stage's state starts on its own cache line: in threaded mode the
 * stages run on different cores at the same time, and a write by one
 * stage must not invalidate the line another stage is reading.  The
 * counters of a stage are added once per job, not once per item. */
struct motion {
	/* read-mostly */
	struct motion_config cfg;
	double T;    /* period, s */
	uint32_t na; /* axes (config.n_axes): items are sized by it */
	double ipm;  /* increments per mm */
	struct sched *sched;
	bool threaded;
	bool loaded; /* an input was chosen (stream written or program) */
	struct source src;
	struct ring q[MOTION_N_QUEUES]; /* q[0] unused (the source) */

	/* error state */
	_Alignas(CL) atomic_bool faulted;
	struct motion_error err;
	pthread_mutex_t err_lock;

	/* decode */
	_Alignas(CL) struct gc_state gc;
	uint32_t lineno;
	atomic_bool dec_end_pending, dec_end_sent, dec_stop;
	atomic_bool dec_busy;
	_Atomic uint64_t n_lines, n_blocks, n_ignored;
	char linebuf[MOTION_MAX_LINE + 2];

	/* fit */
	_Alignas(CL) struct gc_block blk;
	atomic_bool fit_have;
	atomic_bool fit_busy;
	uint32_t fit_k, fit_n;
	double fit_prev[MOTION_MAX_AXES];
	_Atomic uint64_t n_segs;

	/* look-ahead window: segment-ring positions of the segments */
	_Alignas(CL) uint32_t *win;
	double *bwd, *jl;
	uint32_t w_head, w_n, W;
	double la_fixed;
	bool la_prev_move, la_flushing;
	double la_prev_u[MOTION_MAX_AXES];
	double la_prev_vmax;

	/* accel */
	_Alignas(CL) _Atomic uint64_t n_profiles;

	/* interp */
	_Alignas(CL) struct profile cur;
	const struct seg *cur_g; /* cur's segment (in the segment ring) */
	bool cur_valid;
	double tau, tau_start;
	atomic_bool interp_moving, interp_done;

	/* consumer (motion_next_setpoint or the sink task) */
	_Alignas(CL) struct motion_setpoint last;
	uint64_t cycle;
	bool underrun;
	uint64_t sink_sum;
	_Atomic uint64_t n_setpoints, n_underruns;

	/* the end of the run, for motion_wait() */
	_Alignas(CL) pthread_mutex_t end_lock;
	pthread_cond_t end_cond;
	atomic_int end_waiters;
};

static bool run_ended(const struct motion *m)
{
	return atomic_load(&m->faulted) || motion_done(m);
}

/* Wake motion_wait() callers if the run has ended.  Called after each
 * change that can end it: the last setpoint taken (interp's end marker,
 * a consumer's release) or a fault.  The fence pairs with the one in
 * motion_wait(): either the waiter sees the change, or this sees the
 * waiter (and then broadcasts under the lock the waiter sleeps on). */
static void notify_end(struct motion *m)
{
	atomic_thread_fence(memory_order_seq_cst);
	if (atomic_load(&m->end_waiters) == 0 || !run_ended(m))
		return;
	pthread_mutex_lock(&m->end_lock);
	pthread_cond_broadcast(&m->end_cond);
	pthread_mutex_unlock(&m->end_lock);
}

static inline const struct seg *seg_at(const struct motion *m, uint32_t pos)
{
	return ring_at(&m->q[Q_SEGS], pos);
}

static void set_error(struct motion *m, enum motion_errcode code, uint32_t line,
		      uint32_t col, const char *fmt, ...)
{
	va_list ap;

	pthread_mutex_lock(&m->err_lock);
	if (!atomic_load(&m->faulted)) {
		m->err.code = code;
		m->err.line = line;
		m->err.column = col;
		va_start(ap, fmt);
		vsnprintf(m->err.msg, sizeof(m->err.msg), fmt, ap);
		va_end(ap);
		atomic_store(&m->faulted, true);
	}
	pthread_mutex_unlock(&m->err_lock);
	notify_end(m);
}

static void record_error(struct motion *m, const struct motion_error *e)
{
	pthread_mutex_lock(&m->err_lock);
	if (!atomic_load(&m->faulted)) {
		m->err = *e;
		atomic_store(&m->faulted, true);
	}
	pthread_mutex_unlock(&m->err_lock);
	notify_end(m);
}

/* ---- stream --------------------------------------------------------- */

static uint32_t src_level(const struct source *s)
{
	return atomic_load_explicit(&s->tail, memory_order_acquire) -
	       atomic_load_explicit(&s->head, memory_order_acquire);
}

static void flow_check(struct motion *m)
{
	struct source *s = &m->src;
	uint32_t lvl = src_level(s);
	int f = atomic_load(&s->flow);

	if ((f == MOTION_FLOW_XON && lvl < s->high) ||
	    (f == MOTION_FLOW_XOFF && lvl > s->low))
		return;
	pthread_mutex_lock(&s->flow_lock);
	lvl = src_level(s);
	f = atomic_load(&s->flow);
	atomic_store(&s->flow_lvl, lvl);
	if (f == MOTION_FLOW_XON && lvl >= s->high) {
		atomic_store(&s->flow, MOTION_FLOW_XOFF);
		atomic_fetch_add(&s->xoff, 1);
		if (m->cfg.flow_cb)
			m->cfg.flow_cb(m->cfg.flow_user, MOTION_FLOW_XOFF);
	} else if (f == MOTION_FLOW_XOFF && lvl <= s->low) {
		atomic_store(&s->flow, MOTION_FLOW_XON);
		atomic_fetch_add(&s->xon, 1);
		if (m->cfg.flow_cb)
			m->cfg.flow_cb(m->cfg.flow_user, MOTION_FLOW_XON);
	}
	pthread_mutex_unlock(&s->flow_lock);
}

long motion_stream_write(struct motion *m, const char *data, size_t len)
{
	struct source *s = &m->src;

	if (atomic_load(&m->faulted) || atomic_load(&s->eos) || s->mem)
		return -1;
	if (!m->loaded) /* once: this line is read by every stage */
		m->loaded = true;
	uint32_t t = atomic_load_explicit(&s->tail, memory_order_relaxed);
	uint32_t h = atomic_load_explicit(&s->head, memory_order_acquire);
	uint32_t room = s->size - (t - h);
	size_t n = len < room ? len : room;
	uint32_t nl = 0;
	for (size_t i = 0; i < n; i++) {
		s->buf[(t + (uint32_t)i) & s->mask] = (unsigned char)data[i];
		nl += data[i] == '\n';
	}
	atomic_store_explicit(&s->tail, t + (uint32_t)n, memory_order_release);
	atomic_fetch_add_explicit(&s->lines_in, nl, memory_order_release);
	uint32_t lvl = t + (uint32_t)n - h;
	if (lvl > atomic_load_explicit(&s->peak, memory_order_relaxed))
		atomic_store_explicit(&s->peak, lvl, memory_order_relaxed);
	flow_check(m);
	if (m->threaded && n)
		sched_kick(m->sched);
	return (long)n;
}

void motion_stream_end(struct motion *m)
{
	m->loaded = true;
	atomic_store(&m->src.eos, true);
	if (m->threaded)
		sched_kick(m->sched);
}

enum motion_flow motion_stream_flow(const struct motion *m)
{
	return (enum motion_flow)atomic_load(&m->src.flow);
}

uint32_t motion_stream_level(const struct motion *m)
{
	return src_level(&m->src);
}

uint32_t motion_stream_event_level(const struct motion *m)
{
	return atomic_load(&m->src.flow_lvl);
}

int motion_load_program(struct motion *m, const char *text, size_t len)
{
	struct source *s = &m->src;

	if (m->loaded)
		return -1;
	s->mem = true;
	s->text = text;
	s->text_len = len;
	s->text_pos = 0;
	uint32_t lines = 0;
	for (size_t i = 0; i < len; i++)
		lines += text[i] == '\n';
	if (len && text[len - 1] != '\n')
		lines++;
	s->text_lines = lines;
	m->loaded = true;
	atomic_store(&s->eos, true);
	return 0;
}

/* Consumer: copies the next line into m->linebuf.  Returns 1 with *n set,
 * 0 if no complete line is available, 2 if the line is too long (consumed
 * up to MOTION_MAX_LINE + 1 characters). */
static int src_next_line(struct motion *m, size_t *n)
{
	struct source *s = &m->src;

	if (s->mem) {
		if (s->text_pos >= s->text_len)
			return 0;
		const char *p = s->text + s->text_pos;
		size_t rest = s->text_len - s->text_pos;
		const char *nl = memchr(p, '\n', rest);
		size_t l = nl ? (size_t)(nl - p) : rest;
		s->text_pos += nl ? l + 1 : l;
		s->text_lines_out++;
		if (l > MOTION_MAX_LINE)
			return 2;
		memcpy(m->linebuf, p, l);
		*n = l;
		return 1;
	}
	uint32_t h = atomic_load_explicit(&s->head, memory_order_relaxed);
	uint32_t t = atomic_load_explicit(&s->tail, memory_order_acquire);
	uint32_t lvl = t - h;
	uint32_t lines = atomic_load_explicit(&s->lines_in, memory_order_acquire) -
			 s->lines_out;
	uint32_t scan = lvl < MOTION_MAX_LINE + 1u ? lvl : MOTION_MAX_LINE + 1u;
	uint32_t i;
	for (i = 0; i < scan; i++)
		if (s->buf[(h + i) & s->mask] == '\n')
			break;
	if (i < scan) { /* complete line of i characters */
		for (uint32_t k = 0; k < i; k++)
			m->linebuf[k] = (char)s->buf[(h + k) & s->mask];
		*n = i;
		atomic_store_explicit(&s->head, h + i + 1u, memory_order_release);
		s->lines_out++;
		flow_check(m);
		return 1;
	}
	if (lvl > MOTION_MAX_LINE) {
		atomic_store_explicit(&s->head, h + scan, memory_order_release);
		flow_check(m);
		return 2;
	}
	if (lines == 0 && atomic_load(&s->eos) &&
	    lvl == src_level(s) && lvl > 0) { /* last line without newline */
		for (uint32_t k = 0; k < lvl; k++)
			m->linebuf[k] = (char)s->buf[(h + k) & s->mask];
		*n = lvl;
		atomic_store_explicit(&s->head, h + lvl, memory_order_release);
		flow_check(m);
		return 1;
	}
	return 0;
}

/* Lines (or the equivalent) the decoder can take now. */
static uint32_t src_avail(struct motion *m)
{
	struct source *s = &m->src;

	if (s->mem)
		return s->text_lines - s->text_lines_out;
	uint32_t lines = atomic_load_explicit(&s->lines_in, memory_order_acquire) -
			 s->lines_out;
	if (lines)
		return lines;
	uint32_t lvl = src_level(s);
	if (lvl > MOTION_MAX_LINE)
		return 1;
	if (lvl > 0 && atomic_load(&s->eos))
		return 1;
	return 0;
}

static void src_discard(struct motion *m)
{
	struct source *s = &m->src;

	if (s->mem) {
		s->text_pos = s->text_len;
		s->text_lines_out = s->text_lines;
		return;
	}
	uint32_t t = atomic_load_explicit(&s->tail, memory_order_acquire);
	s->lines_out = atomic_load_explicit(&s->lines_in, memory_order_acquire);
	atomic_store_explicit(&s->head, t, memory_order_release);
	flow_check(m);
}

/* ---- decode ---------------------------------------------------------- */

static bool src_eof(struct motion *m)
{
	return atomic_load(&m->src.eos) && src_avail(m) == 0;
}

static void decode_levels(void *arg, uint32_t *ul, uint32_t *dl, uint32_t *dcap)
{
	struct motion *m = arg;

	*dl = ring_count(&m->q[Q_BLOCKS]);
	*dcap = m->q[Q_BLOCKS].cap;
	if (m->dec_end_sent) {
		*ul = m->dec_stop ? src_avail(m) : 0; /* discard after the end */
		if (*ul)
			*dl = 0; /* discarding needs no room */
		return;
	}
	if (m->dec_end_pending || m->dec_stop) {
		*ul = 1;
		return;
	}
	*ul = src_avail(m);
	if (*ul == 0 && src_eof(m))
		*ul = 1; /* end of stream: emit the end marker */
}

static void emit_end_block(struct motion *m)
{
	struct gc_block *b = ring_slot(&m->q[Q_BLOCKS]);

	if (!b)
		return;
	memset(b, 0, sizeof(*b));
	b->kind = GC_END;
	b->line = m->lineno;
	ring_commit(&m->q[Q_BLOCKS]);
	m->dec_end_pending = false;
	m->dec_end_sent = true;
}

static uint32_t decode_run(void *arg, unsigned worker)
{
	struct motion *m = arg;
	uint32_t done = 0;
	uint64_t lines = 0, blocks = 0;
	size_t n;

	(void)worker;
	atomic_store(&m->dec_busy, true);
	while (done < m->cfg.batch) {
		if (m->dec_end_sent) {
			if (m->dec_stop && src_avail(m)) { /* after M2 / error */
				uint64_t before = m->src.mem ? m->src.text_lines_out
							     : m->src.lines_out;
				src_discard(m);
				uint64_t after = m->src.mem ? m->src.text_lines_out
							    : m->src.lines_out;
				atomic_fetch_add(&m->n_ignored, after - before);
			}
			break;
		}
		if (m->dec_end_pending) {
			emit_end_block(m);
			if (m->dec_end_pending)
				break;
			done++;
			continue;
		}
		if (atomic_load(&m->faulted)) {
			m->dec_stop = true;
			m->dec_end_pending = true;
			continue;
		}
		struct gc_block *b = ring_slot(&m->q[Q_BLOCKS]);
		if (!b)
			break;
		int r = src_next_line(m, &n);
		if (r == 0) {
			if (src_eof(m))
				m->dec_end_pending = true;
			if (!m->dec_end_pending)
				break;
			continue;
		}
		m->lineno++;
		lines++;
		done++;
		if (r == 2) {
			set_error(m, MOTION_E_LINE_TOO_LONG, m->lineno,
				  MOTION_MAX_LINE + 1u,
				  "line longer than %d characters", MOTION_MAX_LINE);
			m->dec_stop = true;
			m->dec_end_pending = true;
			continue;
		}
		struct motion_error e;
		if (gc_line(&m->gc, m->linebuf, n, m->lineno, b, &e)) {
			record_error(m, &e);
			m->dec_stop = true;
			m->dec_end_pending = true;
			continue;
		}
		if (b->kind != GC_NONE) {
			ring_commit(&m->q[Q_BLOCKS]);
			blocks++;
		}
		if (m->gc.ended) { /* M2 / M30: the rest is not executed */
			m->dec_stop = true;
			m->dec_end_pending = true;
		}
	}
	atomic_fetch_add_explicit(&m->n_lines, lines, memory_order_relaxed);
	atomic_fetch_add_explicit(&m->n_blocks, blocks, memory_order_relaxed);
	atomic_store(&m->dec_busy, false);
	return done;
}

/* ---- curve fitting ---------------------------------------------------- */

static void seg_limits(const struct motion *m, struct seg *s, double feed,
		       bool rapid)
{
	const struct motion_config *c = &m->cfg;
	double share = c->junction_share;
	double v = rapid ? INFINITY : feed, a = INFINITY, j = INFINITY;

	for (uint32_t k = 0; k < c->n_axes; k++) {
		double au = fabs(SEG_U(s, m->na)[k]);
		if (au < 1e-12)
			continue;
		double vk = c->axis[k].vmax / au;
		double ak = (1.0 - share) * c->axis[k].amax / au;
		double jk = (1.0 - share) * c->axis[k].jmax / au;
		v = vk < v ? vk : v;
		a = ak < a ? ak : a;
		j = jk < j ? jk : j;
	}
	/* every segment lasts at least one cycle, so that no sampling
	 * interval straddles two junctions */
	double vt = s->len / m->T;
	s->vmax = vt < v ? vt : v;
	s->amax = a;
	s->jmax = c->jerk_limited ? j : INFINITY;
}

static bool make_move(const struct motion *m, struct seg *s, const double *p0,
		      const double *p1, uint32_t line, double feed, bool rapid)
{
	const uint32_t n = m->na;
	double *sp0 = SEG_P0(s, n), *sp1 = SEG_P1(s, n), *su = SEG_U(s, n);
	double l2 = 0;

	/* the axes from n_axes on never move (the decoder rejects their
	 * words), so they would only add exact zeros to the length */
	s->kind = SEG_MOVE;
	s->line = line;
	s->dwell = 0;
	for (uint32_t k = 0; k < n; k++) {
		sp0[k] = p0[k];
		sp1[k] = p1[k];
		double d = p1[k] - p0[k];
		l2 += d * d;
	}
	s->len = sqrt(l2);
	if (s->len < 1e-9)
		return false;
	for (uint32_t k = 0; k < n; k++)
		su[k] = (p1[k] - p0[k]) / s->len;
	seg_limits(m, s, feed, rapid);
	return true;
}

static uint32_t arc_segments(const struct motion *m, const struct gc_block *b)
{
	double r = b->r0 > b->r1 ? b->r0 : b->r1;
	double tol = m->cfg.chord_tol;
	double phi = tol < r ? 2.0 * acos(1.0 - tol / r) : PI / 2;

	if (phi > PI / 2)
		phi = PI / 2;
	double n = ceil(fabs(b->sweep) / phi);
	if (n < 1)
		n = 1;
	if (n > 1e7)
		n = 1e7;
	return (uint32_t)n;
}

static void arc_point(const struct gc_block *b, uint32_t k, uint32_t n, double *p)
{
	if (k >= n) {
		memcpy(p, b->end, sizeof(b->end));
		return;
	}
	double f = (double)k / (double)n;
	for (uint32_t i = 0; i < MOTION_MAX_AXES; i++)
		p[i] = b->start[i] + (b->end[i] - b->start[i]) * f;
	double th = b->theta0 + b->sweep * f;
	double r = b->r0 + (b->r1 - b->r0) * f;
	p[b->a0] = b->c0 + r * cos(th);
	p[b->a1] = b->c1 + r * sin(th);
}

static void fit_levels(void *arg, uint32_t *ul, uint32_t *dl, uint32_t *dcap)
{
	struct motion *m = arg;

	*ul = ring_count(&m->q[Q_BLOCKS]) + (m->fit_have ? 1u : 0u);
	*dl = ring_count(&m->q[Q_SEGS]);
	*dcap = m->q[Q_SEGS].cap;
}

static uint32_t fit_run(void *arg, unsigned worker)
{
	struct motion *m = arg;
	uint32_t done = 0;
	uint64_t segs = 0;

	(void)worker;
	atomic_store(&m->fit_busy, true);
	while (done < m->cfg.batch) {
		struct seg *s = ring_slot(&m->q[Q_SEGS]);
		if (!s)
			break;
		if (!m->fit_have) {
			if (!ring_pop(&m->q[Q_BLOCKS], &m->blk))
				break;
			m->fit_have = true;
			m->fit_k = 0;
			memcpy(m->fit_prev, m->blk.start, sizeof(m->fit_prev));
			switch (m->blk.kind) {
			case GC_ARC:
				m->fit_n = arc_segments(m, &m->blk);
				break;
			case GC_DWELL:
				memset(s, 0, m->q[Q_SEGS].elem);
				s->kind = SEG_DWELL;
				s->line = m->blk.line;
				s->dwell = m->blk.dwell;
				memcpy(SEG_P0(s, m->na), m->blk.start,
				       m->na * sizeof(double));
				memcpy(SEG_P1(s, m->na), m->blk.start,
				       m->na * sizeof(double));
				ring_commit(&m->q[Q_SEGS]);
				m->fit_have = false;
				done++;
				continue;
			case GC_END:
				memset(s, 0, m->q[Q_SEGS].elem);
				s->kind = SEG_END;
				s->line = m->blk.line;
				ring_commit(&m->q[Q_SEGS]);
				m->fit_have = false;
				done++;
				continue;
			default:
				m->fit_n = 1;
				break;
			}
		}
		double p[MOTION_MAX_AXES];
		m->fit_k++;
		if (m->blk.kind == GC_ARC)
			arc_point(&m->blk, m->fit_k, m->fit_n, p);
		else
			memcpy(p, m->blk.end, sizeof(p));
		if (make_move(m, s, m->fit_prev, p, m->blk.line, m->blk.feed,
			      m->blk.kind == GC_RAPID)) {
			ring_commit(&m->q[Q_SEGS]);
			segs++;
			memcpy(m->fit_prev, p, sizeof(p));
		}
		done++;
		if (m->fit_k >= m->fit_n)
			m->fit_have = false;
	}
	atomic_fetch_add_explicit(&m->n_segs, segs, memory_order_relaxed);
	atomic_store(&m->fit_busy, false);
	return done;
}

/* ---- look-ahead --------------------------------------------------------- */

static double junction_limit(const struct motion *m, const double *u1,
			     const double *u2, double vmax1, double vmax2)
{
	const struct motion_config *c = &m->cfg;
	double v = vmax1 < vmax2 ? vmax1 : vmax2;

	for (uint32_t k = 0; k < c->n_axes; k++) {
		double du = fabs(u2[k] - u1[k]);
		if (du < 1e-12)
			continue;
		/* the velocity step of a corner lands in one sampling
		 * interval: keep it within the reserved share of the
		 * acceleration (and, two corners per jerk window, jerk) */
		double va = c->junction_share * c->axis[k].amax * m->T / du;
		if (va < v)
			v = va;
		if (c->jerk_limited) {
			double vj = c->junction_share * c->axis[k].jmax * m->T *
				    m->T / (2.0 * du);
			if (vj < v)
				v = vj;
		}
	}
	return v;
}

static double reach(const struct motion *m, const struct seg *s, double v)
{
	if (s->kind != SEG_MOVE)
		return v;
	return plan_reach(v, s->len, s->amax, s->jmax, m->cfg.jerk_limited);
}

#define WIN(m, i) (((m)->w_head + (i)) % (m)->W)

static void la_add(struct motion *m, uint32_t pos)
{
	const struct seg *s = seg_at(m, pos);
	uint32_t n = m->w_n, idx = WIN(m, n);
	double jl = 0;

	if (s->kind == SEG_MOVE) {
		const double *u = SEG_U(s, m->na);
		if (m->la_prev_move)
			jl = junction_limit(m, m->la_prev_u, u, m->la_prev_vmax,
					    s->vmax);
		memcpy(m->la_prev_u, u, m->na * sizeof(double));
		m->la_prev_vmax = s->vmax;
		m->la_prev_move = true;
	} else {
		m->la_prev_move = false;
	}
	m->win[idx] = pos;
	m->jl[idx] = jl;
	double b = reach(m, s, 0.0); /* the newest segment ends at rest */
	m->bwd[idx] = b < jl ? b : jl;
	m->w_n = n + 1;
	/* backward pass: raise the entry speeds the new exit allows; stop
	 * where nothing changes any more */
	for (uint32_t i = n; i-- > 0;) {
		uint32_t k = WIN(m, i);
		double nb = reach(m, seg_at(m, m->win[k]), m->bwd[WIN(m, i + 1)]);
		if (nb > m->jl[k])
			nb = m->jl[k];
		if (nb <= m->bwd[k])
			break;
		m->bwd[k] = nb;
	}
}

static bool la_emit(struct motion *m)
{
	struct planned *p = ring_slot(&m->q[Q_PLANNED]);

	if (!p || m->w_n == 0)
		return false;
	uint32_t k = WIN(m, 0);
	const struct seg *s = seg_at(m, m->win[k]);
	double v0 = m->la_fixed, v1 = 0;
	if (s->kind == SEG_MOVE && m->w_n >= 2) {
		v1 = m->bwd[WIN(m, 1)];
		double f = reach(m, s, v0); /* forward pass */
		if (f < v1)
			v1 = f;
	}
	if (s->kind != SEG_MOVE)
		v0 = v1 = 0;
	p->seg = m->win[k];
	p->kind = s->kind;
	p->v0 = v0;
	p->v1 = v1;
	ring_commit(&m->q[Q_PLANNED]);
	m->la_fixed = v1;
	m->w_head = (m->w_head + 1) % m->W;
	m->w_n--;
	return true;
}

/* Emit without a full window when nothing more can arrive for now (the
 * input is dry) or, in threaded mode, when the setpoint supply runs low. */
static bool la_starving(const struct motion *m)
{
	struct motion *mm = (struct motion *)m;

	/* upstream first: data only moves downstream, so a stage found
	 * empty cannot be refilled behind our back except by new input */
	if (!atomic_load(&m->dec_busy)) {
		uint32_t ul, dl, cap;
		decode_levels(mm, &ul, &dl, &cap);
		if (ul == 0 && ring_count(&m->q[Q_BLOCKS]) == 0 &&
		    !atomic_load(&m->fit_busy) && !atomic_load(&m->fit_have) &&
		    ring_count(&m->q[Q_SEGS]) == 0)
			return true;
	}
	if (m->threaded && !m->cfg.drain_sink &&
	    ring_count(&m->q[Q_PLANNED]) == 0 &&
	    ring_count(&m->q[Q_PROFILES]) == 0 &&
	    ring_count(&m->q[Q_SETPOINTS]) < m->q[Q_SETPOINTS].cap / 4)
		return true;
	return false;
}

static void la_levels(void *arg, uint32_t *ul, uint32_t *dl, uint32_t *dcap)
{
	struct motion *m = arg;
	uint32_t u = 0;

	if (m->w_n < m->W && !m->la_flushing)
		u += ring_count(&m->q[Q_SEGS]);
	if (m->w_n > 0 && (m->w_n == m->W || m->la_flushing || la_starving(m)))
		u += m->w_n;
	if (m->la_flushing && m->w_n == 0)
		u += 1;
	*ul = u;
	*dl = ring_count(&m->q[Q_PLANNED]);
	*dcap = m->q[Q_PLANNED].cap;
}

static uint32_t la_run(void *arg, unsigned worker)
{
	struct motion *m = arg;
	uint32_t done = 0;

	(void)worker;
	while (done < m->cfg.batch) {
		if (m->w_n < m->W && !m->la_flushing) {
			const struct seg *s = ring_front(&m->q[Q_SEGS]);
			if (s) {
				if (s->kind == SEG_END)
					m->la_flushing = true;
				else
					la_add(m, ring_front_pos(&m->q[Q_SEGS]));
				ring_release(&m->q[Q_SEGS]);
				done++;
				continue;
			}
		}
		if (m->w_n > 0 &&
		    (m->w_n == m->W || m->la_flushing || la_starving(m))) {
			if (!la_emit(m))
				break;
			done++;
			continue;
		}
		if (m->la_flushing && m->w_n == 0) {
			struct planned *p = ring_slot(&m->q[Q_PLANNED]);
			if (!p)
				break;
			memset(p, 0, sizeof(*p));
			p->kind = SEG_END;
			ring_commit(&m->q[Q_PLANNED]);
			m->la_flushing = false;
			m->la_prev_move = false;
			m->la_fixed = 0;
			done++;
			continue;
		}
		break;
	}
	return done;
}

/* ---- acceleration planning ------------------------------------------------ */

static void accel_levels(void *arg, uint32_t *ul, uint32_t *dl, uint32_t *dcap)
{
	struct motion *m = arg;

	*ul = ring_count(&m->q[Q_PLANNED]);
	*dl = ring_count(&m->q[Q_PROFILES]);
	*dcap = m->q[Q_PROFILES].cap;
}

static uint32_t accel_run(void *arg, unsigned worker)
{
	struct motion *m = arg;
	uint32_t done = 0;

	(void)worker;
	while (done < m->cfg.batch) {
		struct timed *p = ring_slot(&m->q[Q_PROFILES]);
		const struct planned *in = ring_front(&m->q[Q_PLANNED]);
		if (!p || !in)
			break;
		p->seg = in->seg;
		p->kind = in->kind;
		p->v0 = in->v0;
		p->v1 = in->v1;
		p->vp = in->kind == SEG_MOVE
				? plan_peak(seg_at(m, in->seg), in->v0, in->v1,
					    m->cfg.jerk_limited)
				: 0.0;
		ring_release(&m->q[Q_PLANNED]);
		ring_commit(&m->q[Q_PROFILES]);
		done++;
	}
	atomic_fetch_add_explicit(&m->n_profiles, done, memory_order_relaxed);
	return done;
}

/* ---- coarse interpolation ----------------------------------------------- */

static int32_t to_inc(double v)
{
	double r = nearbyint(v);
	if (r != r)
		return 0; /* not reached: positions are finite */
	if (r > 2147483647.0)
		return INT32_MAX;
	if (r < -2147483648.0)
		return INT32_MIN;
	return (int32_t)r;
}

/* Setpoints travel through their ring compactly, sized by the number of
 * axes n: int32 line, pos[n], vel[n] (status MOVING, cycle assigned by the
 * consumer).  sp_unpack() makes the public struct motion_setpoint. */
static inline size_t sp_size(uint32_t n_axes)
{
	return (1u + 2u * n_axes) * sizeof(int32_t);
}

static void sp_unpack(const struct motion *m, const int32_t *c,
		      struct motion_setpoint *sp)
{
	const uint32_t n = m->na;

	memset(sp, 0, sizeof(*sp));
	sp->n_axes = (uint8_t)n;
	sp->line = (uint32_t)c[0];
	sp->status = MOTION_ST_MOVING;
	memcpy(sp->pos, c + 1, n * sizeof(int32_t));
	memcpy(sp->vel, c + 1 + n, n * sizeof(int32_t));
}

static void make_setpoint(const struct motion *m, int32_t *sp,
			  const struct profile *p, const struct seg *g,
			  double tau, bool at_end)
{
	const uint32_t n = m->na;
	const double *p0 = SEG_P0(g, n), *p1 = SEG_P1(g, n), *u = SEG_U(g, n);
	double s = 0, v = 0;

	sp[0] = (int32_t)g->line;
	if (!at_end && p->kind == SEG_MOVE)
		plan_eval(p, g->len, tau, &s, &v);
	bool end = at_end || (p->kind == SEG_MOVE && s >= g->len);
	double f = g->len > 0 ? s / g->len : 0.0;
	for (uint32_t k = 0; k < n; k++) {
		double x = end ? p1[k] : p0[k] + (p1[k] - p0[k]) * f;
		sp[1 + k] = to_inc(x * m->ipm);
		sp[1 + n + k] = at_end ? 0 : to_inc(v * u[k] * m->ipm);
	}
}

static void interp_levels(void *arg, uint32_t *ul, uint32_t *dl, uint32_t *dcap)
{
	struct motion *m = arg;
	uint32_t q = ring_count(&m->q[Q_PROFILES]);

	*ul = q;
	if (m->cur_valid && (m->tau <= m->cur.dur || q > 0 || m->cur.v1 <= 1e-9))
		*ul += 1;
	*dl = ring_count(&m->q[Q_SETPOINTS]);
	*dcap = m->q[Q_SETPOINTS].cap;
}

/* Makes a planned segment the current one: expands its timed profile. */
static void interp_take(struct motion *m, const struct timed *t)
{
	m->cur_g = seg_at(m, t->seg);
	plan_profile(&m->cur, m->cur_g, t->v0, t->vp, t->v1, m->cfg.jerk_limited);
}

static uint32_t interp_run(void *arg, unsigned worker)
{
	struct motion *m = arg;
	uint32_t done = 0;
	struct ring *out = &m->q[Q_SETPOINTS];

	(void)worker;
	while (done < m->cfg.batch) {
		if (!m->cur_valid) {
			const struct timed *p = ring_front(&m->q[Q_PROFILES]);
			if (!p)
				break;
			if (p->kind == SEG_END) {
				ring_release(&m->q[Q_PROFILES]);
				atomic_store(&m->interp_done, true);
				notify_end(m);
				done++;
				continue;
			}
			atomic_store(&m->interp_done, false);
			interp_take(m, p);
			ring_release(&m->q[Q_PROFILES]);
			m->cur_valid = true;
			m->tau = m->tau_start;
			atomic_store(&m->interp_moving, true);
		}
		if (m->tau <= m->cur.dur) {
			int32_t *sp = ring_slot(out);
			if (!sp)
				break;
			make_setpoint(m, sp, &m->cur, m->cur_g, m->tau, false);
			ring_commit(out);
			m->tau += m->T;
			done++;
			continue;
		}
		/* past the end of the current profile */
		const struct timed *nx = ring_front(&m->q[Q_PROFILES]);
		if (nx && nx->kind != SEG_END) {
			m->tau -= m->cur.dur;
			interp_take(m, nx);
			ring_release(&m->q[Q_PROFILES]);
			continue;
		}
		if (m->cur.v1 > 1e-9)
			break; /* moving: wait for the next profile */
		/* at rest: one sample exactly at the end point, then idle */
		int32_t *sp = ring_slot(out);
		if (!sp)
			break;
		make_setpoint(m, sp, &m->cur, m->cur_g, m->tau, true);
		ring_commit(out);
		m->cur_valid = false;
		m->tau_start = m->T;
		atomic_store(&m->interp_moving, false);
		done++;
	}
	return done;
}

/* ---- benchmark sink --------------------------------------------------------- */

static void sink_levels(void *arg, uint32_t *ul, uint32_t *dl, uint32_t *dcap)
{
	struct motion *m = arg;

	*ul = ring_count(&m->q[Q_SETPOINTS]);
	*dl = 0;
	*dcap = 1;
}

static uint32_t sink_run(void *arg, unsigned worker)
{
	struct motion *m = arg;
	struct ring *q = &m->q[Q_SETPOINTS];
	const int32_t *c;
	int32_t last[1 + 2 * MOTION_MAX_AXES];
	uint32_t done = 0;

	(void)worker;
	while (done < m->cfg.batch * 4 && (c = ring_front(q)) != NULL) {
		for (uint32_t k = 0; k < m->na; k++)
			m->sink_sum += (uint64_t)(uint32_t)c[1 + k];
		memcpy(last, c, q->elem);
		ring_release(q);
		m->cycle++;
		done++;
	}
	if (done)
		sp_unpack(m, last, &m->last);
	atomic_fetch_add_explicit(&m->n_setpoints, done, memory_order_relaxed);
	if (done)
		notify_end(m);
	return done;
}

/* ---- periodic tasks (threaded mode) -------------------------------------- */

static void sample_levels(void *arg, uint32_t *v)
{
	struct motion *m = arg;

	v[Q_STREAM] = m->src.mem ? (uint32_t)(m->src.text_len - m->src.text_pos)
				 : src_level(&m->src);
	for (unsigned q = 1; q < MOTION_N_QUEUES; q++)
		v[q] = ring_count(&m->q[q]);
}

static uint32_t monitor_run(void *arg, unsigned worker)
{
	struct motion *m = arg;

	(void)worker;
	if (m->threaded)
		sched_sample(m->sched);
	return 1;
}

static uint32_t send_run(void *arg, unsigned worker)
{
	struct motion *m = arg;
	struct motion_setpoint sp;

	(void)worker;
	if (!m->threaded)
		return 0;
	motion_next_setpoint(m, &sp);
	m->cfg.send_cb(m->cfg.send_user, &sp);
	return 1;
}

/* ---- setup ----------------------------------------------------------------- */

void motion_config_default(struct motion_config *c)
{
	memset(c, 0, sizeof(*c));
	c->n_axes = 3;
	c->period_us = 1000;
	c->increments_per_mm = 1000.0;
	for (int k = 0; k < MOTION_MAX_AXES; k++) {
		c->axis[k].vmax = 200.0;
		c->axis[k].amax = 2000.0;
		c->axis[k].jmax = 200000.0;
		c->axis[k].min = -1000.0;
		c->axis[k].max = 1000.0;
	}
	c->chord_tol = 0.001;
	c->junction_share = 0.5;
	c->lookahead = 32;
	c->stream_size = 16384;
	c->stream_high = 12288;
	c->stream_low = 4096;
	c->q_blocks = 64;
	c->q_segments = 256;
	c->q_planned = 64;
	c->q_profiles = 64;
	c->q_setpoints = 64;
	c->batch = 8;
	c->policy = MOTION_POLICY_HYBRID;
	c->trace_samples = 0;
	c->monitor_period_us = 10000;
}

static int cfg_fail(struct motion_error *err, const char *msg, int k)
{
	if (err) {
		memset(err, 0, sizeof(*err));
		err->code = MOTION_E_CONFIG;
		if (k >= 0)
			snprintf(err->msg, sizeof(err->msg), "axis %d: %s", k, msg);
		else
			snprintf(err->msg, sizeof(err->msg), "%s", msg);
	}
	return -1;
}

static int check_config(const struct motion_config *c, struct motion_error *err)
{
	const double lim = 2147483647.0;

	if (c->n_axes < 1 || c->n_axes > MOTION_MAX_AXES)
		return cfg_fail(err, "n_axes must be 1..6", -1);
	if (c->period_us < 50 || c->period_us > 100000)
		return cfg_fail(err, "period_us must be 50..100000", -1);
	if (!(c->increments_per_mm > 0) || !isfinite(c->increments_per_mm))
		return cfg_fail(err, "increments_per_mm must be > 0", -1);
	for (uint32_t k = 0; k < c->n_axes; k++) {
		const struct motion_axis_limits *a = &c->axis[k];
		if (!(a->vmax > 0) || !(a->amax > 0) || !isfinite(a->vmax) ||
		    !isfinite(a->amax))
			return cfg_fail(err, "vmax and amax must be > 0", (int)k);
		if (c->jerk_limited && (!(a->jmax > 0) || !isfinite(a->jmax)))
			return cfg_fail(err, "jmax must be > 0", (int)k);
		if (!(a->min < a->max))
			return cfg_fail(err, "travel min must be below max", (int)k);
		if (fabs(a->min) * c->increments_per_mm >= lim ||
		    fabs(a->max) * c->increments_per_mm >= lim)
			return cfg_fail(err, "travel does not fit int32 increments", (int)k);
		if (a->vmax * c->increments_per_mm >= lim)
			return cfg_fail(err, "vmax does not fit int32 increments/s", (int)k);
		if (c->start_pos[k] < a->min || c->start_pos[k] > a->max)
			return cfg_fail(err, "start position outside the travel", (int)k);
	}
	if (!(c->chord_tol > 0))
		return cfg_fail(err, "chord_tol must be > 0", -1);
	if (!(c->junction_share > 0 && c->junction_share < 1))
		return cfg_fail(err, "junction_share must be in (0, 1)", -1);
	if (c->lookahead < 2 || c->lookahead > 4096)
		return cfg_fail(err, "lookahead must be 2..4096", -1);
	if (c->stream_size < 2u * (MOTION_MAX_LINE + 1u) || c->stream_size > (1u << 28))
		return cfg_fail(err, "stream_size must be >= 514 bytes", -1);
	if (!(c->stream_low < c->stream_high && c->stream_high <= c->stream_size))
		return cfg_fail(err, "need stream_low < stream_high <= stream_size", -1);
	if (c->q_blocks < 2 || c->q_segments < 2 || c->q_planned < 2 ||
	    c->q_profiles < 2 || c->q_setpoints < 4)
		return cfg_fail(err, "queue capacities too small", -1);
	if (c->batch < 1 || c->batch > 4096)
		return cfg_fail(err, "batch must be 1..4096", -1);
	if (c->min_job > 4096)
		return cfg_fail(err, "min_job must be 0..4096", -1);
	return 0;
}

int motion_create(const struct motion_config *cfg, struct motion **out,
		  struct motion_error *err)
{
	struct motion *m;
	uint32_t size = 1;

	*out = NULL;
	if (check_config(cfg, err))
		return -1;
	/* cache-line aligned (see struct motion); aligned_alloc wants a
	 * multiple of the alignment */
	m = aligned_alloc(CL, (sizeof(*m) + CL - 1) / CL * CL);
	if (!m)
		goto nomem;
	memset(m, 0, sizeof(*m));
	m->cfg = *cfg;
	m->T = cfg->period_us * 1e-6;
	m->na = cfg->n_axes;
	m->ipm = cfg->increments_per_mm;
	pthread_mutex_init(&m->err_lock, NULL);
	pthread_mutex_init(&m->end_lock, NULL);
	{
		pthread_condattr_t ca;

		pthread_condattr_init(&ca);
		pthread_condattr_setclock(&ca, CLOCK_MONOTONIC);
		pthread_cond_init(&m->end_cond, &ca);
		pthread_condattr_destroy(&ca);
	}
	pthread_mutex_init(&m->src.flow_lock, NULL);
	while (size < cfg->stream_size)
		size <<= 1;
	m->src.buf = calloc(size, 1);
	m->src.size = cfg->stream_size;
	m->src.mask = size - 1u;
	m->src.high = cfg->stream_high;
	m->src.low = cfg->stream_low;
	atomic_init(&m->src.flow, MOTION_FLOW_XON);
	atomic_init(&m->src.flow_lvl, 0);
	if (!m->src.buf ||
	    ring_init(&m->q[Q_BLOCKS], sizeof(struct gc_block), cfg->q_blocks) ||
	    /* segments are referred to by their slot until interpolation is
	     * done with them: a slot is reused only after the segment ring,
	     * the look-ahead window, the planned and profile queues and the
	     * current profile have all moved past it */
	    ring_init_slots(&m->q[Q_SEGS], seg_size(cfg->n_axes), cfg->q_segments,
			    cfg->q_segments + cfg->lookahead + cfg->q_planned +
				    cfg->q_profiles + 4u) ||
	    ring_init(&m->q[Q_PLANNED], sizeof(struct planned), cfg->q_planned) ||
	    ring_init(&m->q[Q_PROFILES], sizeof(struct timed), cfg->q_profiles) ||
	    ring_init(&m->q[Q_SETPOINTS], sp_size(cfg->n_axes), cfg->q_setpoints))
		goto nomem;
	m->W = cfg->lookahead;
	m->win = calloc(m->W, sizeof(*m->win));
	m->bwd = calloc(m->W, sizeof(*m->bwd));
	m->jl = calloc(m->W, sizeof(*m->jl));
	if (!m->win || !m->bwd || !m->jl)
		goto nomem;
	gc_init(&m->gc, cfg);
	m->tau_start = m->T;
	m->last.n_axes = (uint8_t)cfg->n_axes;
	for (uint32_t k = 0; k < cfg->n_axes; k++)
		m->last.pos[k] = to_inc(cfg->start_pos[k] * m->ipm);

	struct sched_task_desc t[MOTION_N_TASKS];
	size_t n = 0;
	memset(t, 0, sizeof(t));
	t[n++] = (struct sched_task_desc){ .name = "decode", .order = 0,
		.levels = decode_levels, .run = decode_run, .arg = m };
	t[n++] = (struct sched_task_desc){ .name = "fit", .order = 1,
		.levels = fit_levels, .run = fit_run, .arg = m };
	t[n++] = (struct sched_task_desc){ .name = "lookahead", .order = 2,
		.levels = la_levels, .run = la_run, .arg = m };
	t[n++] = (struct sched_task_desc){ .name = "accel", .order = 3,
		.levels = accel_levels, .run = accel_run, .arg = m };
	t[n++] = (struct sched_task_desc){ .name = "interp", .order = 4,
		.levels = interp_levels, .run = interp_run, .arg = m };
	if (cfg->drain_sink)
		t[n++] = (struct sched_task_desc){ .name = "sink", .order = 5,
			.levels = sink_levels, .run = sink_run, .arg = m };
	if (cfg->send_cb)
		t[n++] = (struct sched_task_desc){ .name = "send", .periodic = true,
			.prio = 0, .period_us = cfg->period_us, .run = send_run,
			.arg = m };
	if (cfg->trace_samples)
		t[n++] = (struct sched_task_desc){ .name = "monitor",
			.periodic = true, .prio = 1,
			.period_us = cfg->monitor_period_us ? cfg->monitor_period_us
							    : 10000,
			.run = monitor_run, .arg = m };
	m->sched = sched_create(cfg->policy, t, n, cfg->trace_samples);
	if (!m->sched)
		goto nomem;
	sched_set_sampler(m->sched, MOTION_N_QUEUES, queue_names, sample_levels, m);
	sched_set_min_job(m->sched, cfg->min_job ? cfg->min_job : cfg->batch);
	*out = m;
	return 0;
nomem:
	motion_destroy(m);
	if (err) {
		memset(err, 0, sizeof(*err));
		err->code = MOTION_E_NOMEM;
		snprintf(err->msg, sizeof(err->msg), "out of memory");
	}
	return -1;
}

void motion_destroy(struct motion *m)
{
	if (!m)
		return;
	if (m->sched) {
		motion_stop(m);
		sched_destroy(m->sched);
	}
	for (unsigned q = 1; q < MOTION_N_QUEUES; q++)
		ring_free(&m->q[q]);
	free(m->src.buf);
	free(m->win);
	free(m->bwd);
	free(m->jl);
	pthread_mutex_destroy(&m->err_lock);
	pthread_mutex_destroy(&m->end_lock);
	pthread_cond_destroy(&m->end_cond);
	pthread_mutex_destroy(&m->src.flow_lock);
	free(m);
}

int motion_start(struct motion *m, unsigned workers)
{
	if (m->threaded)
		return -1;
	m->threaded = true;
	if (sched_start(m->sched, workers)) {
		m->threaded = false;
		return -1;
	}
	return 0;
}

void motion_stop(struct motion *m)
{
	if (!m->threaded)
		return;
	sched_stop(m->sched);
	m->threaded = false;
}

/* ---- the per-cycle call ------------------------------------------------------- */

uint32_t motion_pump(struct motion *m, uint32_t max_jobs)
{
	uint32_t n = 0;

	if (m->threaded)
		return 0;
	while (n < max_jobs) {
		struct sched_choice c = sched_step(m->sched);
		if (c.kind == SCHED_CHOICE_IDLE)
			break;
		n++;
	}
	return n;
}

static enum motion_status hold(struct motion *m, struct motion_setpoint *out,
			       enum motion_status st)
{
	*out = m->last;
	memset(out->vel, 0, sizeof(out->vel));
	out->cycle = m->cycle++;
	out->status = (uint8_t)st;
	return st;
}

enum motion_status motion_next_setpoint(struct motion *m,
					 struct motion_setpoint *out)
{
	struct ring *q = &m->q[Q_SETPOINTS];

	if (m->underrun)
		return hold(m, out, MOTION_ST_UNDERRUN);
	if (!m->threaded) {
		while (ring_count(q) == 0) {
			struct sched_choice c = sched_step(m->sched);
			if (c.kind == SCHED_CHOICE_IDLE)
				break;
		}
		if (m->cfg.trace_samples) {
			uint32_t every = m->cfg.monitor_period_us / m->cfg.period_us;
			if (m->cycle % (every ? every : 1u) == 0)
				sched_sample(m->sched);
		}
	}
	const int32_t *c = ring_front(q);
	if (c) {
		sp_unpack(m, c, out);
		ring_release(q);
		out->cycle = m->cycle++;
		m->last = *out;
		atomic_fetch_add_explicit(&m->n_setpoints, 1, memory_order_relaxed);
		if (m->threaded) {
			sched_kick(m->sched);
			notify_end(m);
		}
		return MOTION_ST_MOVING;
	}
	bool faulted = atomic_load(&m->faulted);
	if (atomic_load(&m->interp_done))
		return hold(m, out, faulted ? MOTION_ST_FAULT : MOTION_ST_DONE);
	if (!atomic_load(&m->interp_moving))
		return hold(m, out, MOTION_ST_IDLE);
	/* moving, and no setpoint: the planner fell behind */
	m->underrun = true;
	atomic_fetch_add(&m->n_underruns, 1);
	set_error(m, MOTION_E_UNDERRUN, 0, 0,
		  "setpoint underrun at cycle %llu: the pipeline fell behind",
		  (unsigned long long)m->cycle);
	return hold(m, out, MOTION_ST_UNDERRUN);
}

const struct motion_error *motion_last_error(const struct motion *m)
{
	return atomic_load(&m->faulted) ? &m->err : NULL;
}

bool motion_done(const struct motion *m)
{
	return atomic_load(&m->interp_done) &&
	       ring_count(&m->q[Q_SETPOINTS]) == 0;
}

int motion_wait(struct motion *m, uint32_t timeout_ms)
{
	struct timespec ts;
	int rc = 0;

	if (!m->threaded)
		return -1;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	ts.tv_sec += (time_t)(timeout_ms / 1000u);
	ts.tv_nsec += (long)(timeout_ms % 1000u) * 1000000L;
	if (ts.tv_nsec >= 1000000000L) {
		ts.tv_sec++;
		ts.tv_nsec -= 1000000000L;
	}
	pthread_mutex_lock(&m->end_lock);
	atomic_fetch_add(&m->end_waiters, 1);
	atomic_thread_fence(memory_order_seq_cst); /* pairs with notify_end */
	while (!run_ended(m) && rc == 0) {
		if (timeout_ms == 0)
			rc = pthread_cond_wait(&m->end_cond, &m->end_lock);
		else
			rc = pthread_cond_timedwait(&m->end_cond, &m->end_lock, &ts);
	}
	atomic_fetch_sub(&m->end_waiters, 1);
	pthread_mutex_unlock(&m->end_lock);
	return run_ended(m) ? 0 : -1;
}

void motion_get_stats(const struct motion *m, struct motion_stats *st)
{
	struct sched_stats ss;

	memset(st, 0, sizeof(*st));
	st->lines = atomic_load(&m->n_lines);
	st->blocks = atomic_load(&m->n_blocks);
	st->segments = atomic_load(&m->n_segs);
	st->profiles = atomic_load(&m->n_profiles);
	st->setpoints = atomic_load(&m->n_setpoints);
	st->cycles = m->cycle;
	st->xoff_events = atomic_load(&m->src.xoff);
	st->xon_events = atomic_load(&m->src.xon);
	st->underruns = atomic_load(&m->n_underruns);
	st->ignored_lines = atomic_load(&m->n_ignored);
	st->peak[Q_STREAM] = atomic_load(&m->src.peak);
	st->cap[Q_STREAM] = m->src.size;
	for (unsigned q = 1; q < MOTION_N_QUEUES; q++) {
		st->peak[q] = atomic_load(&m->q[q].peak);
		st->cap[q] = m->q[q].cap;
	}
	sched_get_stats(m->sched, &ss);
	st->n_tasks = (uint32_t)ss.n_tasks;
	st->workers = ss.workers;
	for (size_t i = 0; i < ss.n_tasks && i < MOTION_N_TASKS; i++) {
		st->task_name[i] = ss.name[i];
		st->busy_ns[i] = ss.busy_ns[i];
		for (unsigned w = 0; w < MOTION_MAX_WORKERS; w++)
			st->runs[i][w] = ss.runs[i][w];
	}
	for (unsigned w = 0; w < MOTION_MAX_WORKERS; w++) {
		st->idle[w] = ss.idle[w];
		st->job_ns[w] = ss.job_ns[w];
		st->sleep_ns[w] = ss.sleep_ns[w];
		st->sched_ns[w] = ss.sched_ns[w];
	}
}

int motion_trace_csv(const struct motion *m, FILE *f)
{
	return sched_trace_csv(m->sched, f);
}

uint64_t motion_sink_checksum(const struct motion *m)
{
	return m->sink_sum;
}
