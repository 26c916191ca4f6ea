/* SPDX-License-Identifier: MIT */
/* The look-ahead stage (see lookahead.h). */
#include "lookahead.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "items.h"
#include "pipeline.h"
#include "plan.h"

int lookahead_init(struct lookahead *la, const struct motion *m,
		   const struct motion_config *cfg, struct ring *in,
		   struct peaks *out)
{
	la->cfg = cfg;
	la->m = m;
	la->in = in;
	la->out = out;
	la->na = cfg->n_axes;
	la->T = cfg->period_us * 1e-6;
	la->W = cfg->lookahead;
	la->win = calloc(la->W, sizeof(*la->win));
	la->bwd = calloc(la->W, sizeof(*la->bwd));
	la->jl = calloc(la->W, sizeof(*la->jl));
	return la->win && la->bwd && la->jl ? 0 : -1;
}

void lookahead_free(struct lookahead *la)
{
	free(la->win);
	free(la->bwd);
	free(la->jl);
}

static double junction_limit(const struct lookahead *la, const double *u1,
			     const double *u2, double vmax1, double vmax2)
{
	const struct motion_config *c = la->cfg;
	double v = vmax1 < vmax2 ? vmax1 : vmax2;

	for (uint32_t k = 0; k < c->n_axes; k++) {
		double du = fabs(u2[k] - u1[k]);
		if (du < 1e-12)
			continue;
		/* the velocity step of a corner lands in one sampling
		 * interval: keep it within the reserved share of the
		 * acceleration (and, two corners per jerk window, jerk) */
		double va = c->junction_share * c->axis[k].amax * la->T / du;
		if (va < v)
			v = va;
		if (c->jerk_limited) {
			double vj = c->junction_share * c->axis[k].jmax * la->T *
				    la->T / (2.0 * du);
			if (vj < v)
				v = vj;
		}
	}
	return v;
}

/*
 * The largest speed the segment reaches from v (entering or, the profiles
 * being symmetric, leaving at v), capped at cap. When the transition from
 * v to cap fits in the segment the answer is cap without solving for the
 * reachable speed: with short segments the cap (a junction limit, the
 * next segment's entry speed) binds in about 99 % of the calls, and the
 * jerk-limited solve was most of the look-ahead's time (issue 24).
 */
static double reach_capped(const struct lookahead *la, const struct seg *s, double v,
			   double cap)
{
	bool jerk = la->cfg->jerk_limited;

	if (s->kind != SEG_MOVE)
		return v < cap ? v : cap;
	if (cap <= v || plan_trans_dist(v, cap, s->amax, s->jmax, jerk) <= s->len)
		return cap;
	double r = plan_reach(v, s->len, s->amax, s->jmax, jerk);
	return r < cap ? r : cap;
}

#define WIN(la, i) (((la)->head + (i)) % (la)->W)

static void la_add(struct lookahead *la, uint32_t pos)
{
	const struct seg *s = seg_at(la->in, pos);
	uint32_t n = la->n, idx = WIN(la, n);
	double jl = 0;

	if (s->kind == SEG_MOVE) {
		const double *u = SEG_U(s, la->na);
		if (la->prev_move)
			jl = junction_limit(la, la->prev_u, u, la->prev_vmax,
					    s->vmax);
		memcpy(la->prev_u, u, la->na * sizeof(double));
		la->prev_vmax = s->vmax;
		la->prev_move = true;
	} else {
		la->prev_move = false;
	}
	la->win[idx] = pos;
	la->jl[idx] = jl;
	la->bwd[idx] = reach_capped(la, s, 0.0, jl); /* the newest ends at rest */
	la->n = n + 1;
	/* backward pass: raise the entry speeds the new exit allows; stop
	 * where nothing changes any more */
	for (uint32_t i = n; i-- > 0;) {
		uint32_t k = WIN(la, i);
		double nb = reach_capped(la, seg_at(la->in, la->win[k]),
					 la->bwd[WIN(la, i + 1)], la->jl[k]);
		if (nb <= la->bwd[k])
			break;
		la->bwd[k] = nb;
	}
}

static bool la_emit(struct lookahead *la)
{
	struct planned *p = peaks_slot(la->out);

	if (!p || la->n == 0)
		return false;
	uint32_t k = WIN(la, 0);
	const struct seg *s = seg_at(la->in, la->win[k]);
	double v0 = la->fixed, v1 = 0;
	if (s->kind == SEG_MOVE && la->n >= 2) {
		/* forward pass */
		v1 = reach_capped(la, s, v0, la->bwd[WIN(la, 1)]);
	}
	if (s->kind != SEG_MOVE)
		v0 = v1 = 0;
	p->seg = la->win[k];
	p->kind = s->kind;
	p->v0 = v0;
	p->v1 = v1;
	p->vp = 0; /* set by the profile lane */
	peaks_commit(la->out);
	la->fixed = v1;
	la->head = (la->head + 1) % la->W;
	la->n--;
	return true;
}

/* The end marker, after the window was emitted to the last segment. */
static bool la_emit_end(struct lookahead *la)
{
	struct planned *p = peaks_slot(la->out);

	if (!p)
		return false;
	memset(p, 0, sizeof(*p));
	p->kind = SEG_END;
	peaks_commit(la->out);
	la->flushing = false;
	la->prev_move = false;
	la->fixed = 0;
	return true;
}

/* The window may take another segment. */
static bool la_can_take(const struct lookahead *la)
{
	return la->n < la->W && !la->flushing;
}

/* The oldest segment may leave. */
static bool la_can_emit(const struct lookahead *la)
{
	return la->n > 0 && (la->n == la->W || la->flushing ||
			     pipeline_starving(la->m));
}

void lookahead_levels(void *arg, uint32_t *ul, uint32_t *dl, uint32_t *dcap)
{
	struct lookahead *la = arg;
	uint32_t u = 0;

	if (la_can_take(la))
		u += ring_count(la->in);
	if (la_can_emit(la))
		u += la->n;
	if (la->flushing && la->n == 0)
		u += 1;
	*ul = u;
	const struct ring *out = peaks_put_ring(la->out);
	*dl = ring_count(out);
	*dcap = out->cap;
}

/* A job takes and emits up to batch segments each, and ends once it has
 * dealt the last segment of a chunk: the profile lane that gets the chunk
 * then finds all of it at once, in one job (and so does accel, which ends
 * its jobs at the same boundaries). */
uint32_t lookahead_run(void *arg, unsigned worker)
{
	struct lookahead *la = arg;
	uint32_t taken = 0, emitted = 0;
	const uint32_t batch = la->cfg->batch;

	(void)worker;
	while (taken < batch && emitted < batch) {
		if (la_can_take(la)) {
			const struct seg *s = ring_front(la->in);
			if (s) {
				if (s->kind == SEG_END)
					la->flushing = true;
				else
					la_add(la, ring_front_pos(la->in));
				ring_release(la->in);
				taken++;
				continue;
			}
		}
		if (la_can_emit(la)) {
			if (!la_emit(la))
				break;
			emitted++;
			if (peaks_put_chunk_done(la->out))
				break;
			continue;
		}
		if (la->flushing && la->n == 0) {
			if (!la_emit_end(la))
				break;
			emitted++;
			continue;
		}
		break;
	}
	return taken + emitted;
}
