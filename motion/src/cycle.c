/* SPDX-License-Identifier: MIT */
/* The consumer end: the per-cycle call and the tasks that stand in for it
 * (see cycle.h). */
#include "cycle.h"

#include <string.h>

#include "items.h"
#include "pipeline_state.h"

/* ---- benchmark sink ------------------------------------------------------ */

/* The lane whose chunk is next to be taken. */
static struct ring *cur_out(struct motion *m)
{
	return &m->ip.lane[m->out.lane].out;
}

/* After taking setpoint c: the last of its chunk moves to the next lane. */
static void chunk_step(struct motion *m, const int32_t *c)
{
	if (c[1] & SP_CHUNK_END)
		m->out.lane = m->out.lane + 1 < m->ip.lanes ? m->out.lane + 1 : 0;
}

void sink_levels(void *arg, uint32_t *ul, uint32_t *dl, uint32_t *dcap)
{
	struct motion *m = arg;

	*ul = ring_count(cur_out(m));
	*dl = 0;
	*dcap = 1;
}

uint32_t sink_run(void *arg, unsigned worker)
{
	struct motion *m = arg;
	struct consumer *o = &m->out;
	const int32_t *c;
	int32_t last[2 + 2 * MOTION_MAX_AXES];
	uint32_t done = 0;

	(void)worker;
	while (done < m->cfg.batch * 4) {
		struct ring *q = cur_out(m);
		if ((c = ring_front(q)) == NULL)
			break;
		o->sink_sum = sp_hash(o->sink_sum, m->na, c);
		memcpy(last, c, q->elem);
		ring_release(q);
		chunk_step(m, last);
		o->cycle++;
		done++;
	}
	if (done)
		sp_unpack(m->na, last, &o->last);
	atomic_fetch_add_explicit(&o->n_setpoints, done, memory_order_relaxed);
	if (done)
		pipeline_notify_end(m);
	return done;
}

/* ---- periodic send task (threaded mode) ---------------------------------- */

uint32_t send_run(void *arg, unsigned worker)
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

/* ---- the per-cycle call -------------------------------------------------- */

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

/* The last position again, at rest, with status st. */
static enum motion_status hold(struct motion *m, struct motion_setpoint *out,
			       enum motion_status st)
{
	*out = m->out.last;
	memset(out->vel, 0, sizeof(out->vel));
	out->cycle = m->out.cycle++;
	out->status = (uint8_t)st;
	return st;
}

/* Synchronous mode: run the pipeline until a setpoint is ready (or nothing
 * can run), and take a queue-level sample every monitor period. */
static void run_synchronous(struct motion *m, const struct ring *q)
{
	while (ring_count(q) == 0) {
		struct sched_choice c = sched_step(m->sched);
		if (c.kind == SCHED_CHOICE_IDLE)
			break;
	}
	if (m->cfg.trace_samples) {
		uint32_t every = m->cfg.monitor_period_us / m->cfg.period_us;
		if (m->out.cycle % (every ? every : 1u) == 0)
			sched_sample(m->sched);
	}
}

/* The last setpoint sent (or none yet) stands still on every axis. */
static bool last_at_rest(const struct motion *m)
{
	const struct motion_setpoint *l = &m->out.last;

	for (unsigned i = 0; i < l->n_axes && i < MOTION_MAX_AXES; i++)
		if (l->vel[i])
			return false;
	return true;
}

/* No setpoint ready: done, idle, or (moving) an underrun. A motion that
 * accel has started from rest but whose first setpoint is not computed
 * yet is not an underrun: the axes stand still, and waiting one more
 * cycle there only delays the motion (the start race of threaded mode,
 * where the send task's cycle can fall between accel taking the segment
 * and a lane producing its first chunk). Only a gap after a moving
 * setpoint breaks the trajectory. */
static enum motion_status no_setpoint(struct motion *m,
				      struct motion_setpoint *out)
{
	bool faulted = pipeline_faulted(m);
	bool moving = atomic_load(&m->ip.active) > 0;
	if (atomic_load(&m->ip.done) && !moving && interp_drained(&m->ip))
		return hold(m, out, faulted ? MOTION_ST_FAULT : MOTION_ST_DONE);
	if (!moving || last_at_rest(m))
		return hold(m, out, MOTION_ST_IDLE);
	/* moving, and no setpoint: the planner fell behind */
	m->out.underrun = true;
	atomic_fetch_add(&m->out.n_underruns, 1);
	pipeline_fail(m, MOTION_E_UNDERRUN, 0, 0,
		      "setpoint underrun at cycle %llu: the pipeline fell behind",
		      (unsigned long long)m->out.cycle);
	return hold(m, out, MOTION_ST_UNDERRUN);
}

enum motion_status motion_next_setpoint(struct motion *m,
					 struct motion_setpoint *out)
{
	struct ring *q = cur_out(m);

	if (m->out.underrun)
		return hold(m, out, MOTION_ST_UNDERRUN);
	if (!m->threaded)
		run_synchronous(m, q);
	const int32_t *c = ring_front(q);
	if (!c)
		return no_setpoint(m, out);
	sp_unpack(m->na, c, out);
	bool next = c[1] & SP_CHUNK_END;
	ring_release(q);
	if (next)
		m->out.lane = m->out.lane + 1 < m->ip.lanes ? m->out.lane + 1 : 0;
	out->cycle = m->out.cycle++;
	m->out.last = *out;
	atomic_fetch_add_explicit(&m->out.n_setpoints, 1, memory_order_relaxed);
	if (m->threaded) {
		sched_kick(m->sched);
		pipeline_notify_end(m);
	}
	return MOTION_ST_MOVING;
}
