/* SPDX-License-Identifier: MIT */
/* The fit stage (see fit.h). */
#include "fit.h"

#include <math.h>
#include <string.h>

#include "items.h"

#define PI 3.14159265358979323846

void fit_init(struct fit *f, const struct motion_config *cfg, struct ring *in,
	      struct ring *out)
{
	f->cfg = cfg;
	f->in = in;
	f->out = out;
	f->na = cfg->n_axes;
	f->T = cfg->period_us * 1e-6;
}

static void seg_limits(const struct fit *f, struct seg *s, double feed,
		       bool rapid)
{
	const struct motion_config *c = f->cfg;
	double share = c->junction_share;
	double v = rapid ? INFINITY : feed, a = INFINITY, j = INFINITY;

	for (uint32_t k = 0; k < c->n_axes; k++) {
		double au = fabs(SEG_U(s, f->na)[k]);
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
	double vt = s->len / f->T;
	s->vmax = vt < v ? vt : v;
	s->amax = a;
	s->jmax = c->jerk_limited ? j : INFINITY;
}

static bool make_move(const struct fit *f, struct seg *s, const double *p0,
		      const double *p1, uint32_t line, double feed, bool rapid)
{
	const uint32_t n = f->na;
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
	seg_limits(f, s, feed, rapid);
	return true;
}

static uint32_t arc_segments(const struct fit *f, const struct gc_block *b)
{
	double r = b->r0 > b->r1 ? b->r0 : b->r1;
	double tol = f->cfg->chord_tol;
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

void fit_levels(void *arg, uint32_t *ul, uint32_t *dl, uint32_t *dcap)
{
	struct fit *f = arg;

	*ul = ring_count(f->in) + (f->have ? 1u : 0u);
	*dl = ring_count(f->out);
	*dcap = f->out->cap;
}

/* A segment that is not a move (dwell, end marker) for the block in hand,
 * written to the slot s. */
static void still_segment(struct fit *f, struct seg *s, enum seg_kind kind)
{
	memset(s, 0, f->out->elem);
	s->kind = kind;
	s->line = f->blk.line;
	if (kind == SEG_DWELL) {
		s->dwell = f->blk.dwell;
		memcpy(SEG_P0(s, f->na), f->blk.start, f->na * sizeof(double));
		memcpy(SEG_P1(s, f->na), f->blk.start, f->na * sizeof(double));
	}
	ring_commit(f->out);
	f->have = false;
}

enum take { TAKE_NONE, TAKE_STILL, TAKE_MOVE };

/* Takes the next block: none left, a dwell or the end marker (its
 * segment is then written to the slot s), or a move to cut. */
static enum take take_block(struct fit *f, struct seg *s)
{
	if (!ring_pop(f->in, &f->blk))
		return TAKE_NONE;
	f->have = true;
	f->k = 0;
	memcpy(f->prev, f->blk.start, sizeof(f->prev));
	switch (f->blk.kind) {
	case GC_ARC:
		f->n = arc_segments(f, &f->blk);
		return TAKE_MOVE;
	case GC_DWELL:
		still_segment(f, s, SEG_DWELL);
		return TAKE_STILL;
	case GC_END:
		still_segment(f, s, SEG_END);
		return TAKE_STILL;
	default:
		f->n = 1;
		return TAKE_MOVE;
	}
}

uint32_t fit_run(void *arg, unsigned worker)
{
	struct fit *f = arg;
	uint32_t done = 0;
	uint64_t segs = 0;
	uint32_t batch = f->cfg->batch;

	(void)worker;
	atomic_store(&f->busy, true);
	while (done < batch) {
		struct seg *s = ring_slot(f->out);
		if (!s)
			break;
		if (!f->have) {
			enum take t = take_block(f, s);
			if (t == TAKE_NONE)
				break;
			if (t == TAKE_STILL) {
				done++;
				continue;
			}
		}
		double p[MOTION_MAX_AXES];
		f->k++;
		if (f->blk.kind == GC_ARC)
			arc_point(&f->blk, f->k, f->n, p);
		else
			memcpy(p, f->blk.end, sizeof(p));
		if (make_move(f, s, f->prev, p, f->blk.line, f->blk.feed,
			      f->blk.kind == GC_RAPID)) {
			ring_commit(f->out);
			segs++;
			memcpy(f->prev, p, sizeof(p));
		}
		done++;
		if (f->k >= f->n)
			f->have = false;
	}
	atomic_fetch_add_explicit(&f->n_segs, segs, memory_order_relaxed);
	atomic_store(&f->busy, false);
	return done;
}
