/* SPDX-License-Identifier: MIT */
/*
 * The pipeline: stream -> decode -> fit -> look-ahead -> profile lanes ->
 * accel -> interpolation lanes -> setpoints, each stage (each lane) a
 * data-dependent task of the hybrid scheduler.
 * This file builds it (motion_create), answers the stages' questions
 * (pipeline.h), and holds the public calls that are not per cycle.
 */
#define _POSIX_C_SOURCE 200809L
#include <pthread.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "config.h"
#include "items.h"
#include "servoamp/mono_clock.h"
#include "pipeline_state.h"

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

/* ---- faults and the end of the run (pipeline.h) ----------------------- */

static bool run_ended(const struct motion *m)
{
	return atomic_load(&m->fault.on) || motion_done(m);
}

/* The fence pairs with the one in motion_wait(): either the waiter sees
 * the change, or this sees the waiter (and then broadcasts under the lock
 * the waiter sleeps on). */
void pipeline_notify_end(struct motion *m)
{
	atomic_thread_fence(memory_order_seq_cst);
	if (atomic_load(&m->end.waiters) == 0 || !run_ended(m))
		return;
	pthread_mutex_lock(&m->end.lock);
	pthread_cond_broadcast(&m->end.cond);
	pthread_mutex_unlock(&m->end.lock);
}

void pipeline_fail(struct motion *m, enum motion_errcode code, uint32_t line,
		   uint32_t col, const char *fmt, ...)
{
	struct fault *f = &m->fault;
	va_list ap;

	pthread_mutex_lock(&f->lock);
	if (!atomic_load(&f->on)) {
		f->err.code = code;
		f->err.line = line;
		f->err.column = col;
		va_start(ap, fmt);
		vsnprintf(f->err.msg, sizeof(f->err.msg), fmt, ap);
		va_end(ap);
		atomic_store(&f->on, true);
	}
	pthread_mutex_unlock(&f->lock);
	pipeline_notify_end(m);
}

void pipeline_record(struct motion *m, const struct motion_error *e)
{
	struct fault *f = &m->fault;

	pthread_mutex_lock(&f->lock);
	if (!atomic_load(&f->on)) {
		f->err = *e;
		atomic_store(&f->on, true);
	}
	pthread_mutex_unlock(&f->lock);
	pipeline_notify_end(m);
}

bool pipeline_faulted(const struct motion *m)
{
	return atomic_load(&m->fault.on);
}

bool pipeline_starving(const struct motion *m)
{
	struct motion *mm = (struct motion *)m;

	/* upstream first: data only moves downstream, so a stage found
	 * empty cannot be refilled behind our back except by new input */
	if (!atomic_load(&m->dec.busy)) {
		uint32_t ul, dl, cap;
		decode_levels(&mm->dec, &ul, &dl, &cap);
		if (ul == 0 && ring_count(&m->q[Q_BLOCKS]) == 0 &&
		    !atomic_load(&m->fit.busy) && !atomic_load(&m->fit.have) &&
		    ring_count(&m->q[Q_SEGS]) == 0)
			return true;
	}
	if (m->threaded && !m->cfg.drain_sink &&
	    peaks_count(&m->pk) == 0 &&
	    interp_in_count(&m->ip) == 0 &&
	    interp_out_count(&m->ip) < interp_out_cap(&m->ip) / 4)
		return true;
	return false;
}

/* With the whole program in (the stream closed), the next segment always
 * comes (the end marker at the latest, also after a fault), so the output
 * does not depend on when it comes: only an open stream that ran dry, or a
 * real-time consumer running short, stops at rest. */
bool pipeline_rest_now(const struct motion *m)
{
	if (!pipeline_starving(m))
		return false;
	return !stream_closed(&m->src) || (m->threaded && !m->cfg.drain_sink);
}

/* ---- input --------------------------------------------------------------- */

long motion_stream_write(struct motion *m, const char *data, size_t len)
{
	if (atomic_load(&m->fault.on) || stream_closed(&m->src))
		return -1;
	if (!m->loaded) /* once: this line is read by every stage */
		m->loaded = true;
	size_t n = stream_write(&m->src, data, len);
	if (n)
		pipeline_kick(m);
	return (long)n;
}

void motion_stream_end(struct motion *m)
{
	m->loaded = true;
	stream_end(&m->src);
	pipeline_kick(m);
}

enum motion_flow motion_stream_flow(const struct motion *m)
{
	return (enum motion_flow)atomic_load(&m->src.flow);
}

uint32_t motion_stream_level(const struct motion *m)
{
	return stream_level(&m->src);
}

uint32_t motion_stream_event_level(const struct motion *m)
{
	return atomic_load(&m->src.flow_lvl);
}

int motion_load_program(struct motion *m, const char *text, size_t len)
{
	if (m->loaded)
		return -1;
	stream_load(&m->src, text, len);
	m->loaded = true;
	stream_end(&m->src);
	return 0;
}

/* The chain's queues; "planned" is the profile lanes' rings, the last two
 * are the interpolation lanes' rings, as one queue each. */
static uint32_t queue_count(const struct motion *m, unsigned q)
{
	if (q == Q_PLANNED)
		return peaks_count(&m->pk);
	if (q == Q_PROFILES)
		return interp_in_count(&m->ip);
	if (q == Q_SETPOINTS)
		return interp_out_count(&m->ip);
	return ring_count(&m->q[q]);
}

static uint32_t queue_cap(const struct motion *m, unsigned q)
{
	if (q == Q_PLANNED)
		return peaks_cap(&m->pk);
	if (q == Q_PROFILES)
		return interp_in_cap(&m->ip);
	if (q == Q_SETPOINTS)
		return interp_out_cap(&m->ip);
	return m->q[q].cap;
}

static uint32_t queue_peak(const struct motion *m, unsigned q)
{
	if (q == Q_PLANNED)
		return peaks_peak(&m->pk);
	if (q == Q_PROFILES)
		return interp_in_peak(&m->ip);
	if (q == Q_SETPOINTS)
		return interp_out_peak(&m->ip);
	return atomic_load(&m->q[q].peak);
}

/* ---- queue-level trace ----------------------------------------------------- */

static void sample_levels(void *arg, uint32_t *v)
{
	struct motion *m = arg;

	v[Q_STREAM] = stream_backlog(&m->src);
	for (unsigned q = 1; q < MOTION_N_QUEUES; q++)
		v[q] = queue_count(m, q);
}

/* Threaded mode: the periodic task that takes the samples. */
static uint32_t monitor_run(void *arg, unsigned worker)
{
	struct motion *m = arg;

	(void)worker;
	if (m->threaded)
		sched_sample(m->sched);
	return 1;
}

/* ---- setup ------------------------------------------------------------------ */

/* A lane's ring: its share of the queue's capacity (at least 4 items), so
 * that the lanes together hold what the one queue held (the profile lanes:
 * in their input rings, and again in their output rings). */
static uint32_t lane_cap(uint32_t q, uint32_t lanes)
{
	uint32_t c = q / lanes;
	return c < 4 ? 4 : c;
}

/* After peaks_init(): the segment ring's slots count the profile lanes'
 * rings (peaks_cap()). */
static int make_rings(struct motion *m, const struct motion_config *cfg)
{
	uint32_t planned = peaks_cap(&m->pk);

	return ring_init(&m->q[Q_BLOCKS], sizeof(struct gc_block), cfg->q_blocks) ||
	       /* segments are referred to by their slot until interpolation
		* is done with them: a slot is reused only after the segment
		* ring, the look-ahead window, the profile lanes' rings and
		* accel's current segment have all moved past it (the pieces
		* dealt to the interpolation lanes carry a copy of their
		* segment) */
	       ring_init_slots(&m->q[Q_SEGS], seg_size(cfg->n_axes),
			       cfg->q_segments,
			       cfg->q_segments + cfg->lookahead + planned + 4u);
}

static const char *const lane_names[INTERP_MAX_LANES] = {
	"interp0", "interp1", "interp2", "interp3",
	"interp4", "interp5", "interp6", "interp7",
};
static const char *const peak_names[PEAK_MAX_LANES] = {
	"peak0", "peak1", "peak2", "peak3",
	"peak4", "peak5", "peak6", "peak7",
};

/* The scheduler's tasks: the stages in chain order, then the optional
 * sink and the periodic tasks. */
static size_t task_table(struct motion *m, struct sched_task_desc *t)
{
	const struct motion_config *cfg = &m->cfg;
	size_t n = 0;

	memset(t, 0, MOTION_N_TASKS * sizeof(*t));
	t[n++] = (struct sched_task_desc){ .name = "decode", .order = 0,
		.levels = decode_levels, .run = decode_run, .arg = &m->dec };
	t[n++] = (struct sched_task_desc){ .name = "fit", .order = 1,
		.levels = fit_levels, .run = fit_run, .arg = &m->fit };
	t[n++] = (struct sched_task_desc){ .name = "lookahead", .order = 2,
		.levels = lookahead_levels, .run = lookahead_run, .arg = &m->la };
	/* the profile lanes, then the interpolation lanes: one task each,
	 * the lanes of a stage at the same place in the chain */
	for (uint32_t k = 0; k < cfg->interp_lanes; k++)
		t[n++] = (struct sched_task_desc){ .name = peak_names[k],
			.order = 3, .levels = peak_levels, .run = peak_run,
			.arg = &m->pk.lane[k] };
	t[n++] = (struct sched_task_desc){ .name = "accel", .order = 4,
		.levels = accel_levels, .run = accel_run, .arg = &m->acc };
	for (uint32_t k = 0; k < cfg->interp_lanes; k++)
		t[n++] = (struct sched_task_desc){ .name = lane_names[k],
			.order = 5, .levels = interp_levels, .run = interp_run,
			.arg = &m->ip.lane[k] };
	if (cfg->drain_sink)
		t[n++] = (struct sched_task_desc){ .name = "sink", .order = 6,
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
	return n;
}

static void init_locks(struct motion *m)
{
	pthread_condattr_t ca;

	pthread_mutex_init(&m->fault.lock, NULL);
	pthread_mutex_init(&m->end.lock, NULL);
	pthread_condattr_init(&ca);
	pthread_condattr_setclock(&ca, CLOCK_MONOTONIC);
	pthread_cond_init(&m->end.cond, &ca);
	pthread_condattr_destroy(&ca);
}

int motion_create(const struct motion_config *cfg, struct motion **out,
		  struct motion_error *err)
{
	struct motion *m;

	*out = NULL;
	if (config_check(cfg, err))
		return -1;
	/* cache-line aligned (see struct motion); aligned_alloc wants a
	 * multiple of the alignment */
	m = aligned_alloc(CL, (sizeof(*m) + CL - 1) / CL * CL);
	if (!m)
		goto nomem;
	memset(m, 0, sizeof(*m));
	m->cfg = *cfg;
	m->na = cfg->n_axes;
	m->ipm = cfg->increments_per_mm;
	cfg = &m->cfg; /* the stages keep a pointer to it */
	init_locks(m);
	if (m->cfg.interp_lanes == 0)
		m->cfg.interp_lanes = MOTION_DEFAULT_LANES;
	if (stream_init(&m->src, cfg) ||
	    peaks_init(&m->pk, cfg, &m->q[Q_SEGS],
		       lane_cap(cfg->q_planned, m->cfg.interp_lanes)) ||
	    make_rings(m, cfg) ||
	    lookahead_init(&m->la, m, cfg, &m->q[Q_SEGS], &m->pk) ||
	    interp_init(&m->ip, m, cfg, &m->q[Q_SEGS], m->acc.issued,
			lane_cap(cfg->q_profiles, m->cfg.interp_lanes),
			lane_cap(cfg->q_setpoints, m->cfg.interp_lanes)))
		goto nomem;
	decode_init(&m->dec, m, cfg, &m->src, &m->q[Q_BLOCKS]);
	fit_init(&m->fit, cfg, &m->q[Q_BLOCKS], &m->q[Q_SEGS]);
	accel_init(&m->acc, m, cfg, &m->pk, &m->ip, &m->q[Q_SEGS]);
	m->out.last.n_axes = (uint8_t)cfg->n_axes;
	for (uint32_t k = 0; k < cfg->n_axes; k++)
		m->out.last.pos[k] = to_inc(cfg->start_pos[k] * m->ipm);

	struct sched_task_desc t[MOTION_N_TASKS];
	size_t n = task_table(m, t);
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
	stream_free(&m->src);
	lookahead_free(&m->la);
	peaks_free(&m->pk);
	interp_free(&m->ip);
	pthread_mutex_destroy(&m->fault.lock);
	pthread_mutex_destroy(&m->end.lock);
	pthread_cond_destroy(&m->end.cond);
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

/* ---- state of the run ---------------------------------------------------- */

const struct motion_error *motion_last_error(const struct motion *m)
{
	return atomic_load(&m->fault.on) ? &m->fault.err : NULL;
}

bool motion_done(const struct motion *m)
{
	return atomic_load(&m->ip.done) && interp_drained(&m->ip);
}

int motion_wait(struct motion *m, uint32_t timeout_ms)
{
	struct end_wait *e = &m->end;
	struct timespec ts;
	int rc = 0;

	if (!m->threaded)
		return -1;
	mono_deadline(&ts, (uint64_t)timeout_ms * 1000000u);
	pthread_mutex_lock(&e->lock);
	atomic_fetch_add(&e->waiters, 1);
	atomic_thread_fence(memory_order_seq_cst); /* pairs with notify_end */
	while (!run_ended(m) && rc == 0) {
		if (timeout_ms == 0)
			rc = pthread_cond_wait(&e->cond, &e->lock);
		else
			rc = pthread_cond_timedwait(&e->cond, &e->lock, &ts);
	}
	atomic_fetch_sub(&e->waiters, 1);
	pthread_mutex_unlock(&e->lock);
	return run_ended(m) ? 0 : -1;
}

void motion_queue_levels(const struct motion *m, uint32_t level[MOTION_N_QUEUES],
			 uint32_t cap[MOTION_N_QUEUES])
{
	level[Q_STREAM] = motion_stream_level(m);
	cap[Q_STREAM] = m->src.size;
	for (unsigned q = 1; q < MOTION_N_QUEUES; q++) {
		level[q] = queue_count(m, q);
		cap[q] = queue_cap(m, q);
	}
}

void motion_get_stats(const struct motion *m, struct motion_stats *st)
{
	struct sched_stats ss;

	memset(st, 0, sizeof(*st));
	st->lines = atomic_load(&m->dec.n_lines);
	st->blocks = atomic_load(&m->dec.n_blocks);
	st->segments = atomic_load(&m->fit.n_segs);
	st->profiles = atomic_load(&m->acc.n_profiles);
	st->setpoints = atomic_load(&m->out.n_setpoints);
	st->cycles = m->out.cycle;
	st->xoff_events = atomic_load(&m->src.xoff);
	st->xon_events = atomic_load(&m->src.xon);
	st->underruns = atomic_load(&m->out.n_underruns);
	st->ignored_lines = atomic_load(&m->dec.n_ignored);
	st->peak[Q_STREAM] = atomic_load(&m->src.peak);
	st->cap[Q_STREAM] = m->src.size;
	for (unsigned q = 1; q < MOTION_N_QUEUES; q++) {
		st->peak[q] = queue_peak(m, q);
		st->cap[q] = queue_cap(m, q);
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

uint64_t motion_setpoint_hash(uint64_t h, const struct motion_setpoint *sp)
{
	int32_t c[2 + 2 * MOTION_MAX_AXES];
	uint32_t n = sp->n_axes <= MOTION_MAX_AXES ? sp->n_axes : MOTION_MAX_AXES;

	c[0] = (int32_t)sp->line;
	c[1] = 0;
	memcpy(c + 2, sp->pos, n * sizeof(int32_t));
	memcpy(c + 2 + n, sp->vel, n * sizeof(int32_t));
	return sp_hash(h, n, c);
}

uint64_t motion_sink_checksum(const struct motion *m)
{
	return m->out.sink_sum;
}
