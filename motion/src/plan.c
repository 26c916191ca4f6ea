/* SPDX-License-Identifier: MIT */
#include <math.h>
#include <string.h>

#include "internal.h"

double plan_trans_time(double dv, double a, double j, bool jerk)
{
	dv = fabs(dv);
	if (!jerk)
		return dv / a;
	if (dv >= a * a / j)
		return dv / a + a / j;
	return 2.0 * sqrt(dv / j);
}

double plan_trans_dist(double va, double vb, double a, double j, bool jerk)
{
	/* symmetric profiles: distance = mean speed * duration */
	return 0.5 * (va + vb) * plan_trans_time(vb - va, a, j, jerk);
}

double plan_reach(double v, double L, double a, double j, bool jerk)
{
	double hi = sqrt(v * v + 2.0 * a * L);

	if (!jerk || L <= 0)
		return hi;
	double lo = v;
	for (int i = 0; i < 48; i++) {
		double mid = 0.5 * (lo + hi);
		if (plan_trans_dist(v, mid, a, j, true) <= L)
			lo = mid;
		else
			hi = mid;
	}
	return lo;
}

static void trans_init(struct trans *t, double va, double vb, double a, double j,
		       bool jerk)
{
	double dv = fabs(vb - va);

	t->va = va;
	t->sigma = vb >= va ? 1.0 : -1.0;
	t->j = j;
	if (!jerk) {
		t->tj = 0;
		t->A = a;
		t->ta = dv / a;
	} else if (dv >= a * a / j) {
		t->A = a;
		t->tj = a / j;
		t->ta = dv / a - a / j;
	} else {
		t->tj = sqrt(dv / j);
		t->A = j * t->tj;
		t->ta = 0;
	}
}

static void trans_eval(const struct trans *t, double x, double *s, double *v)
{
	double sg = t->sigma, A = t->A, j = t->j, tj = t->tj, ta = t->ta;

	if (x < 0)
		x = 0;
	if (x < tj) {
		*v = t->va + sg * j * x * x / 2.0;
		*s = t->va * x + sg * j * x * x * x / 6.0;
		return;
	}
	double v1 = t->va, s1 = 0;
	if (tj > 0) {
		v1 += sg * A * tj / 2.0;
		s1 = t->va * tj + sg * j * tj * tj * tj / 6.0;
	}
	x -= tj;
	if (x < ta) {
		*v = v1 + sg * A * x;
		*s = s1 + v1 * x + sg * A * x * x / 2.0;
		return;
	}
	double v2 = v1 + sg * A * ta;
	double s2 = s1 + v1 * ta + sg * A * ta * ta / 2.0;
	x -= ta;
	if (x > tj)
		x = tj;
	if (tj > 0) {
		*v = v2 + sg * (A * x - j * x * x / 2.0);
		*s = s2 + v2 * x + sg * (A * x * x / 2.0 - j * x * x * x / 6.0);
	} else {
		*v = v2;
		*s = s2;
	}
}

double plan_peak(const struct seg *g, double v0, double v1, bool jerk)
{
	double a = g->amax, j = g->jmax, L = g->len, vp;

	if (g->kind != SEG_MOVE)
		return 0.0;
	double vlo = v0 > v1 ? v0 : v1;
	if (!jerk) {
		vp = sqrt((2.0 * a * L + v0 * v0 + v1 * v1) / 2.0);
		if (vp > g->vmax)
			vp = g->vmax;
	} else if (plan_trans_dist(v0, g->vmax, a, j, true) +
			   plan_trans_dist(g->vmax, v1, a, j, true) <= L) {
		vp = g->vmax;
	} else {
		double lo = vlo, hi = g->vmax;
		for (int i = 0; i < 48; i++) {
			double mid = 0.5 * (lo + hi);
			if (plan_trans_dist(v0, mid, a, j, true) +
				    plan_trans_dist(mid, v1, a, j, true) <= L)
				lo = mid;
			else
				hi = mid;
		}
		vp = lo;
	}
	if (vp < vlo)
		vp = vlo;
	return vp;
}

void plan_profile(struct profile *p, const struct seg *g, double v0, double vp,
		  double v1, bool jerk)
{
	double a = g->amax, j = g->jmax, L = g->len;
	struct trans tr1, tr3;

	memset(p, 0, sizeof(*p));
	p->kind = g->kind;
	if (g->kind != SEG_MOVE) {
		p->dur = g->kind == SEG_DWELL ? g->dwell : 0.0;
		return;
	}
	p->v0 = v0;
	p->v1 = v1;
	p->vp = vp;
	trans_init(&tr1, v0, vp, a, j, jerk);
	trans_init(&tr3, vp, v1, a, j, jerk);
	p->j = j;
	p->sg1 = tr1.sigma > 0 ? 1 : -1;
	p->A1 = tr1.A;
	p->tj1 = tr1.tj;
	p->ta1 = tr1.ta;
	p->sg3 = tr3.sigma > 0 ? 1 : -1;
	p->A3 = tr3.A;
	p->tj3 = tr3.tj;
	p->ta3 = tr3.ta;
	p->t1 = 2.0 * tr1.tj + tr1.ta;
	double t3 = 2.0 * tr3.tj + tr3.ta;
	p->d1 = 0.5 * (v0 + vp) * p->t1;
	double d3 = 0.5 * (vp + v1) * t3;
	double d2 = L - p->d1 - d3;
	if (d2 < 0)
		d2 = 0;
	p->d2 = d2;
	p->t2 = vp > 0 ? d2 / vp : 0.0;
	p->dur = p->t1 + p->t2 + t3;
}

void plan_eval(const struct profile *p, double len, double t, double *s, double *v)
{
	double ds, vv;

	if (p->kind != SEG_MOVE) {
		*s = 0;
		*v = 0;
		return;
	}
	if (t >= p->dur) {
		*s = len;
		*v = p->v1;
		return;
	}
	if (t < p->t1) {
		struct trans tr = { p->v0, (double)p->sg1, p->A1, p->j, p->tj1, p->ta1 };
		trans_eval(&tr, t, &ds, &vv);
	} else if (t < p->t1 + p->t2) {
		ds = p->d1 + p->vp * (t - p->t1);
		vv = p->vp;
	} else {
		struct trans tr = { p->vp, (double)p->sg3, p->A3, p->j, p->tj3, p->ta3 };
		trans_eval(&tr, t - p->t1 - p->t2, &ds, &vv);
		ds += p->d1 + p->d2;
	}
	if (ds > len)
		ds = len;
	if (ds < 0)
		ds = 0;
	*s = ds;
	*v = vv < 0 ? 0 : vv;
}
