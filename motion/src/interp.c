/* SPDX-License-Identifier: MIT */
/* The interpolation lanes (see interp.h). */
#include "interp.h"

#include <stdlib.h>
#include <string.h>

#include "items.h"
#include "pipeline.h"

#ifdef MOTION_TEST_HOOKS
/* Tests only (the Makefile compiles a second interp.o with
 * -DMOTION_TEST_HOOKS for test_end_wait): called by a lane just before it
 * releases a piece whose setpoints are all committed, so that a test can
 * hold the lane there while other workers run. */
void (*interp_test_release_hook)(const struct interp_lane *l,
				 const struct piece *pc);
#define INTERP_TEST_POINT(l, pc)                                 \
	do {                                                     \
		if (interp_test_release_hook)                    \
			interp_test_release_hook((l), (pc));     \
	} while (0)
#else
#define INTERP_TEST_POINT(l, pc) ((void)0)
#endif

int interp_init(struct interp *ip, struct motion *m,
		const struct motion_config *cfg, const struct ring *segs,
		const _Atomic uint64_t *issued, uint32_t lane_in,
		uint32_t lane_out)
{
	ip->m = m;
	ip->segs = segs;
	ip->na = cfg->n_axes;
	ip->batch = cfg->batch;
	ip->lanes = cfg->interp_lanes;
	ip->T = cfg->period_us * 1e-6;
	ip->ipm = cfg->increments_per_mm;
	ip->jerk = cfg->jerk_limited;
	for (uint32_t k = 0; k < ip->lanes; k++) {
		struct interp_lane *l = &ip->lane[k];
		l->ip = ip;
		l->id = k;
		l->issued = &issued[k];
		if (ring_init(&l->in, piece_size(cfg->n_axes), lane_in) ||
		    ring_init(&l->out, sp_size(cfg->n_axes), lane_out))
			return -1;
	}
	return 0;
}

void interp_free(struct interp *ip)
{
	for (uint32_t k = 0; k < INTERP_MAX_LANES; k++) {
		ring_free(&ip->lane[k].in);
		ring_free(&ip->lane[k].out);
	}
}

void interp_sample(const struct interp *ip, int32_t *sp,
		   const struct profile *p, const struct seg *g, double tau,
		   bool at_end)
{
	const uint32_t n = ip->na;
	const double *p0 = SEG_P0(g, n), *p1 = SEG_P1(g, n), *u = SEG_U(g, n);
	double s = 0, v = 0;

	sp[0] = (int32_t)g->line;
	sp[1] = 0;
	if (!at_end && p->kind == SEG_MOVE)
		plan_eval(p, g->len, tau, &s, &v);
	bool end = at_end || (p->kind == SEG_MOVE && s >= g->len);
	double f = g->len > 0 ? s / g->len : 0.0;
	for (uint32_t k = 0; k < n; k++) {
		double x = end ? p1[k] : p0[k] + (p1[k] - p0[k]) * f;
		sp[2 + k] = to_inc(x * ip->ipm);
		sp[2 + n + k] = at_end ? 0 : to_inc(v * u[k] * ip->ipm);
	}
}

/* UL: samples dealt to the lane and not produced yet (the accel stage
 * publishes what it dealt after each piece, the lane what it produced
 * after each job; levels are read only while the lane does not run). */
void interp_levels(void *arg, uint32_t *ul, uint32_t *dl, uint32_t *dcap)
{
	struct interp_lane *l = arg;
	uint64_t is = atomic_load_explicit(l->issued, memory_order_acquire);
	uint64_t pr = atomic_load_explicit(&l->produced, memory_order_relaxed);
	uint64_t d = is - pr;

	*ul = d > UINT32_MAX ? UINT32_MAX : (uint32_t)d;
	if (*ul == 0 && ring_count(&l->in) > 0)
		*ul = 1; /* not reached: a piece has a sample */
	*dl = ring_count(&l->out);
	*dcap = l->out.cap;
}

uint32_t interp_run(void *arg, unsigned worker)
{
	struct interp_lane *l = arg;
	struct interp *ip = l->ip;
	const double T = ip->T;
	uint32_t done = 0, released = 0;

	(void)worker;
	while (done < ip->batch) {
		const struct piece *pc = ring_front(&l->in);
		if (!pc)
			break;
		if (!l->have) {
			l->g = piece_seg((void *)pc);
			l->tau = pc->tau0;
			l->i = 0;
			l->have = true;
		}
		const bool at_end = pc->flags & PIECE_AT_END;
		const bool chunk_end = pc->flags & PIECE_CHUNK_END;
		while (l->i < pc->n && done < ip->batch) {
			int32_t *sp = ring_slot(&l->out);
			if (!sp)
				goto out;
			interp_sample(ip, sp, &pc->prof, l->g, l->tau, false);
			l->i++;
			if (chunk_end && !at_end && l->i == pc->n)
				sp[1] = SP_CHUNK_END;
			ring_commit(&l->out);
			l->tau += T;
			done++;
		}
		if (l->i < pc->n)
			break; /* the job's batch is full */
		if (at_end) {
			if (done >= ip->batch)
				break;
			int32_t *sp = ring_slot(&l->out);
			if (!sp)
				break;
			interp_sample(ip, sp, &pc->prof, l->g, l->tau, true);
			if (chunk_end)
				sp[1] = SP_CHUNK_END;
			ring_commit(&l->out);
			done++;
			/* at rest: the motion that accel started has ended */
			atomic_fetch_sub(&ip->active, 1);
		}
		INTERP_TEST_POINT(l, pc);
		ring_release(&l->in);
		l->have = false;
		released++;
	}
out:
	atomic_fetch_add_explicit(&l->produced, done, memory_order_release);
	/* Releasing a piece can end the run: motion_done() wants every lane's
	 * input ring empty as well as every output ring, and the consumer may
	 * have taken this piece's last setpoint (and found the piece still
	 * here, so not woken motion_wait()) between our commit and this
	 * release.  Then nothing else is left to run, so the wake-up is ours
	 * to give. */
	if (released)
		pipeline_notify_end(ip->m);
	return done;
}

uint32_t interp_in_count(const struct interp *ip)
{
	uint32_t n = 0;
	for (uint32_t k = 0; k < ip->lanes; k++)
		n += ring_count(&ip->lane[k].in);
	return n;
}

uint32_t interp_out_count(const struct interp *ip)
{
	uint32_t n = 0;
	for (uint32_t k = 0; k < ip->lanes; k++)
		n += ring_count(&ip->lane[k].out);
	return n;
}

uint32_t interp_in_cap(const struct interp *ip)
{
	uint32_t n = 0;
	for (uint32_t k = 0; k < ip->lanes; k++)
		n += ip->lane[k].in.cap;
	return n;
}

uint32_t interp_out_cap(const struct interp *ip)
{
	uint32_t n = 0;
	for (uint32_t k = 0; k < ip->lanes; k++)
		n += ip->lane[k].out.cap;
	return n;
}

uint32_t interp_in_peak(const struct interp *ip)
{
	uint32_t n = 0;
	for (uint32_t k = 0; k < ip->lanes; k++)
		n += atomic_load(&ip->lane[k].in.peak);
	return n;
}

uint32_t interp_out_peak(const struct interp *ip)
{
	uint32_t n = 0;
	for (uint32_t k = 0; k < ip->lanes; k++)
		n += atomic_load(&ip->lane[k].out.peak);
	return n;
}

/* Upstream first: a lane releases a piece only after committing its last
 * setpoint, so empty input rings mean every setpoint is in an output
 * ring.  A lane's release can therefore be what makes this true (the
 * consumer took the last setpoint before the release): interp_run()
 * calls pipeline_notify_end() after releasing. */
bool interp_drained(const struct interp *ip)
{
	for (uint32_t k = 0; k < ip->lanes; k++)
		if (ring_count(&ip->lane[k].in))
			return false;
	for (uint32_t k = 0; k < ip->lanes; k++)
		if (ring_count(&ip->lane[k].out))
			return false;
	return true;
}
