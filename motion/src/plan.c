/* SPDX-License-Identifier: MIT */
#include <float.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "plan.h"

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

/* Jerk-limited speed planning solves "the largest speed whose transitions
 * fit in a length" (look-ahead: one transition; accel planning: the two
 * transitions of a segment).  The distance is continuous, increasing and
 * piecewise smooth in that speed (a transition that reaches the
 * acceleration limit, or one that does not), so a Newton iteration with a
 * starting point from the closed form converges in a few steps; it is kept
 * inside a bracket [feasible, infeasible] and falls back to bisection when
 * a step would leave it (plan_peak first tries peak_short(), Newton in a
 * variable where the distance is smooth).  The answer is always on the
 * feasible side: the transitions of the returned speed fit in the length. */

struct fit_problem {
	double u0, u1; /* the fixed speeds (reach: u1 unused) */
	bool two;      /* two transitions (peak) or one (reach) */
	double L, a, j;
};

/* The distance of the transition u -> w (w >= u), as plan_trans_dist()
 * gives it bit for bit, and in *dd its derivative in w: one square root
 * for both (the pair is most of the solver's time). */
static double trans_dist_ddw(double u, double w, double a, double j, double *dd)
{
	double dv = w - u;

	if (dv >= a * a / j) {
		*dd = w / a + 0.5 * a / j;
		return 0.5 * (u + w) * (dv / a + a / j);
	}
	double r = sqrt(dv / j); /* half the transition time */
	*dd = r > 0 ? r + (u + w) / (2.0 * j * r) : INFINITY;
	return 0.5 * (u + w) * (2.0 * r);
}

static double fit_excess(const struct fit_problem *p, double w, double *dd)
{
	double d = trans_dist_ddw(p->u0, w, p->a, p->j, dd);

	if (p->two) {
		double dd1;

		d += trans_dist_ddw(p->u1, w, p->a, p->j, &dd1);
		*dd += dd1;
	}
	return d - p->L;
}

/* The largest w in [lo, hi] with fit_excess(w) <= 0, given that
 * fit_excess(lo) <= 0 < fit_excess(hi), starting from x. */
static double fit_solve(const struct fit_problem *p, double lo, double hi, double x)
{
	const double tol = 16.0 * DBL_EPSILON;

	for (int i = 0; i < 100 && hi - lo > tol * hi; i++) {
		if (!(x > lo && x < hi))
			x = 0.5 * (lo + hi);
		double dd, f = fit_excess(p, x, &dd);
		if (f <= 0)
			lo = x;
		else
			hi = x;
		double step = f / dd;
		if (!(dd > 0) || !isfinite(step)) {
			x = 0.5 * (lo + hi);
			continue;
		}
		/* x fits and Newton puts the root within the tolerance above
		 * it: done, without an evaluation on the other side to close
		 * the bracket (plan_peak: 5.3 evaluations a solve before) */
		if (f <= 0 && -step <= tol * x)
			return x;
		/* near the root, step just across it so that the bracket
		 * closes from both sides instead of creeping from one */
		if (fabs(step) < tol * x)
			step += f > 0 ? 0.5 * tol * x : -0.5 * tol * x;
		x -= step;
	}
	return lo;
}

/* A cube root to about 1e-10 relative, for first guesses only (the C
 * library's cbrt() was a fifth of plan_peak's instructions): a third of
 * the exponent from the bits, then three Newton steps. */
static double cbrt_guess(double x)
{
	uint64_t u;
	double y;

	if (!(x > 0))
		return 0.0;
	memcpy(&u, &x, sizeof(u));
	u = u / 3u + 0x2A9F7893782DA1CEull;
	memcpy(&y, &u, sizeof(y));
	for (int i = 0; i < 3; i++)
		y = (2.0 * y + x / (y * y)) * (1.0 / 3.0);
	return y;
}

/* The end speed of a jerk-limited transition from v over exactly L, in
 * closed form: a transition that reaches a (speed change at least
 * c = a^2/j) is a quadratic in the end speed; a shorter one ends at
 * v + j h^2 with j h^3 + 2 v h = L (h: half its duration), a cubic whose
 * real root Cardano's formula gives (its cube root by cbrt_guess(), to
 * about 1e-10).  It can be on either side of the true speed; it is a
 * starting point for fit_solve() and peak_short(). */
static double reach_guess(double v, double L, double a, double j)
{
	double c = a * a / j;

	if (L >= (2.0 * v + c) * a / j) {
		double d = c - 2.0 * v;
		return 0.5 * (sqrt(d * d + 8.0 * a * L) - c);
	}
	double q = 0.5 * L / j, pp = 2.0 * v / (3.0 * j);
	double r = cbrt_guess(q + sqrt(q * q + pp * pp * pp));
	double h = r > 0 ? r - pp / r : 0.0;
	return v + j * h * h;
}

double plan_reach(double v, double L, double a, double j, bool jerk)
{
	double hi = sqrt(v * v + 2.0 * a * L);

	if (!jerk || L <= 0)
		return hi;
	const struct fit_problem p = { v, 0.0, false, L, a, j };
	double dd;
	if (fit_excess(&p, hi, &dd) <= 0)
		return hi; /* not reached: a jerk limit only lengthens it */
	return fit_solve(&p, v, hi, reach_guess(v, L, a, j));
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

/* The two jerk-limited transitions v0 -> w -> v1 fit in L. */
static bool peak_fits(double v0, double w, double v1, double L, double a, double j)
{
	return plan_trans_dist(v0, w, a, j, true) + plan_trans_dist(w, v1, a, j, true) <= L;
}

/*
 * plan_peak's solve when both transitions are short at the answer (a speed
 * change under a^2/j: no constant-acceleration phase). With w = vhi + s^2
 * the two distances,
 *   ((2 vhi + s^2) s + (vlo + vhi + s^2) sqrt(vhi - vlo + s^2)) / sqrt(j),
 * are smooth and convex in s, where in w the vhi side's square root has an
 * infinite slope at vhi: Newton from the guess takes about 2.6 steps of one
 * square root each, against 4.1 evaluations of two in fit_solve(). The
 * answer is checked with plan_trans_dist(), as fit_solve()'s are, and
 * lowered an ulp at a time (at most 4) until it fits. A negative return:
 * not in this regime, or not found; the caller then uses fit_solve().
 */
static double peak_short(double v0, double v1, double L, double a, double j, double vmax,
			 double guess)
{
	double vlo = v0 < v1 ? v0 : v1, vhi = v0 < v1 ? v1 : v0;
	double dv = vhi - vlo, b = vlo + vhi, Lj = L * sqrt(j);
	double s = guess > vhi ? sqrt(guess - vhi) : 0.0;

	/* f and f' times sqrt(j), f' times r too: one division a step */
	for (int i = 0; i < 12 && s > 0; i++) {
		double s2 = s * s, r = sqrt(dv + s2);
		double f = (2.0 * vhi + s2) * s + (b + s2) * r - Lj;
		double dfr = (2.0 * vhi + 3.0 * s2 + 2.0 * s * r) * r + (b + s2) * s;
		double step = f * r / dfr;

		s -= step;
		if (fabs(step) <= 1e-9 * s)
			break;
	}
	if (!(s > 0))
		return -1.0;
	double w = vhi + s * s;
	if (!(w - vlo < a * a / j) || w > vmax)
		return -1.0;
	for (int k = 0; k < 4; k++) {
		if (peak_fits(v0, w, v1, L, a, j))
			return w;
		w = nextafter(w, 0.0);
	}
	return -1.0;
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
	} else if (peak_fits(v0, g->vmax, v1, L, a, j)) {
		vp = g->vmax;
	} else {
		/* first guess: with equal entry and exit speeds u the peak is
		 * reached from u over half the length; take u as their mean.
		 * Unequal speeds u -+ h raise it: with short transitions (the
		 * distance about 2w sqrt((w - v)/j) each) the peak x above u
		 * becomes x_s + h^2 / (4 x_s), x_s the peak of equal speeds.
		 * (Mean error of the guess on the benchmark's short arcs:
		 * 0.8 % without the term, 0.12 % with it; 4.7 evaluations a
		 * solve become 4.1.) */
		double u = 0.5 * (v0 + v1), h = 0.5 * fabs(v1 - v0);
		double guess = reach_guess(u, 0.5 * L, a, j);
		if (guess > u)
			guess += h * h / (4.0 * (guess - u));
		const struct fit_problem p = { v0, v1, true, L, a, j };
		if (!peak_fits(v0, vlo, v1, L, a, j)) {
			vp = vlo; /* the pair alone does not fit */
		} else {
			vp = peak_short(v0, v1, L, a, j, g->vmax, guess);
			if (vp < 0)
				vp = fit_solve(&p, vlo, g->vmax, guess);
		}
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
