/* SPDX-License-Identifier: MIT */
/* The interpolation stage (see interp.h). */
#include "interp.h"

#include "items.h"
#include "pipeline.h"

void interp_init(struct interp *ip, struct motion *m,
		 const struct motion_config *cfg, struct ring *in,
		 struct ring *out, const struct ring *segs)
{
	ip->m = m;
	ip->in = in;
	ip->out = out;
	ip->segs = segs;
	ip->na = cfg->n_axes;
	ip->batch = cfg->batch;
	ip->T = cfg->period_us * 1e-6;
	ip->ipm = cfg->increments_per_mm;
	ip->jerk = cfg->jerk_limited;
	ip->tau_start = ip->T;
}

static void make_setpoint(const struct interp *ip, int32_t *sp,
			  const struct profile *p, const struct seg *g,
			  double tau, bool at_end)
{
	const uint32_t n = ip->na;
	const double *p0 = SEG_P0(g, n), *p1 = SEG_P1(g, n), *u = SEG_U(g, n);
	double s = 0, v = 0;

	sp[0] = (int32_t)g->line;
	if (!at_end && p->kind == SEG_MOVE)
		plan_eval(p, g->len, tau, &s, &v);
	bool end = at_end || (p->kind == SEG_MOVE && s >= g->len);
	double f = g->len > 0 ? s / g->len : 0.0;
	for (uint32_t k = 0; k < n; k++) {
		double x = end ? p1[k] : p0[k] + (p1[k] - p0[k]) * f;
		sp[1 + k] = to_inc(x * ip->ipm);
		sp[1 + n + k] = at_end ? 0 : to_inc(v * u[k] * ip->ipm);
	}
}

void interp_levels(void *arg, uint32_t *ul, uint32_t *dl, uint32_t *dcap)
{
	struct interp *ip = arg;
	uint32_t q = ring_count(ip->in);

	*ul = q;
	if (ip->cur_valid &&
	    (ip->tau <= ip->cur.dur || q > 0 || ip->cur.v1 <= 1e-9))
		*ul += 1;
	*dl = ring_count(ip->out);
	*dcap = ip->out->cap;
}

/* Makes a planned segment the current one: expands its timed profile. */
static void interp_take(struct interp *ip, const struct timed *t)
{
	ip->cur_g = seg_at(ip->segs, t->seg);
	plan_profile(&ip->cur, ip->cur_g, t->v0, t->vp, t->v1, ip->jerk);
}

/* No current segment: take the next one, or pass the end marker on.
 * Returns false if there is nothing to take. */
static bool interp_start(struct interp *ip, uint32_t *done)
{
	const struct timed *p = ring_front(ip->in);
	if (!p)
		return false;
	if (p->kind == SEG_END) {
		ring_release(ip->in);
		atomic_store(&ip->done, true);
		pipeline_notify_end(ip->m);
		(*done)++;
		return true;
	}
	atomic_store(&ip->done, false);
	interp_take(ip, p);
	ring_release(ip->in);
	ip->cur_valid = true;
	ip->tau = ip->tau_start;
	atomic_store(&ip->moving, true);
	return true;
}

/* Past the end of the current profile: go on into the next segment, wait
 * for it while moving, or stop at the end point.  Returns false when the
 * job must end here. */
static bool interp_past_end(struct interp *ip, uint32_t *done)
{
	const struct timed *nx = ring_front(ip->in);
	if (nx && nx->kind != SEG_END) {
		ip->tau -= ip->cur.dur;
		interp_take(ip, nx);
		ring_release(ip->in);
		return true;
	}
	if (ip->cur.v1 > 1e-9)
		return false; /* moving: wait for the next profile */
	/* at rest: one sample exactly at the end point, then idle */
	int32_t *sp = ring_slot(ip->out);
	if (!sp)
		return false;
	make_setpoint(ip, sp, &ip->cur, ip->cur_g, ip->tau, true);
	ring_commit(ip->out);
	ip->cur_valid = false;
	ip->tau_start = ip->T;
	atomic_store(&ip->moving, false);
	(*done)++;
	return true;
}

uint32_t interp_run(void *arg, unsigned worker)
{
	struct interp *ip = arg;
	uint32_t done = 0;

	(void)worker;
	while (done < ip->batch) {
		if (!ip->cur_valid) {
			if (!interp_start(ip, &done))
				break;
			if (!ip->cur_valid)
				continue; /* the end marker */
		}
		if (ip->tau <= ip->cur.dur) {
			int32_t *sp = ring_slot(ip->out);
			if (!sp)
				break;
			make_setpoint(ip, sp, &ip->cur, ip->cur_g, ip->tau, false);
			ring_commit(ip->out);
			ip->tau += ip->T;
			done++;
			continue;
		}
		if (!interp_past_end(ip, &done))
			break;
	}
	return done;
}
