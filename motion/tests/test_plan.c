/* SPDX-License-Identifier: MIT */
/*
 * The jerk-limited speed solvers (plan_reach, plan_peak) against a plain
 * bisection over the same distance function: the same speeds to 1e-9
 * relative, and always on the safe side (the transitions of the returned
 * speed fit in the segment).  Random problems over the ranges a machine
 * tool sees, plus the edges (at rest, tiny and huge lengths, transitions
 * at the boundary between the two kinds).
 */
#define _POSIX_C_SOURCE 200809L
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "plan.h"

static uint64_t rng = 0x9e3779b97f4a7c15ull;

static double urand(void)
{
	rng ^= rng << 13;
	rng ^= rng >> 7;
	rng ^= rng << 17;
	return (double)(rng >> 11) / 9007199254740992.0;
}

/* log-uniform in [lo, hi] */
static double lrand(double lo, double hi)
{
	return lo * pow(hi / lo, urand());
}

/* Distance of the transition u0 -> w, plus w -> u1 when `both`. */
static double ref_dist(double u0, double w, double u1, bool both, double a, double j)
{
	double d = plan_trans_dist(u0, w, a, j, true);

	return both ? d + plan_trans_dist(w, u1, a, j, true) : d;
}

/* The reference: up to 200 bisection steps over [lo, hi], keeping the
 * end whose transitions fit in L. */
static double ref_bisect(double u0, double u1, bool both, double lo, double hi,
			 double L, double a, double j)
{
	for (int i = 0; i < 200 && hi > lo; i++) {
		double mid = 0.5 * (lo + hi);
		if (mid <= lo || mid >= hi)
			break;
		if (ref_dist(u0, mid, u1, both, a, j) <= L)
			lo = mid;
		else
			hi = mid;
	}
	return lo;
}

static double ref_reach(double v, double L, double a, double j)
{
	return ref_bisect(v, 0.0, false, v, sqrt(v * v + 2.0 * a * L), L, a, j);
}

static double two(double v0, double vp, double v1, double a, double j)
{
	return ref_dist(v0, vp, v1, true, a, j);
}

static double ref_peak(double v0, double v1, double vmax, double L, double a, double j)
{
	if (two(v0, vmax, v1, a, j) <= L)
		return vmax;
	return ref_bisect(v0, v1, true, v0 > v1 ? v0 : v1, vmax, L, a, j);
}

#define CLOSE(x, ref) (fabs((x) - (ref)) <= 1e-9 * (fabs(ref) > 1.0 ? fabs(ref) : 1.0))

static int check_reach(double v, double L, double a, double j)
{
	double r = plan_reach(v, L, a, j, true), ref = ref_reach(v, L, a, j);

	CHECK(isfinite(r) && r >= v, "reach(v=%g L=%g a=%g j=%g) = %g", v, L, a, j, r);
	CHECK(plan_trans_dist(v, r, a, j, true) <= L,
	      "reach(v=%g L=%g a=%g j=%g) = %.17g needs %.17g > L", v, L, a, j, r,
	      plan_trans_dist(v, r, a, j, true));
	CHECK(CLOSE(r, ref), "reach(v=%g L=%g a=%g j=%g) = %.17g, bisection %.17g", v,
	      L, a, j, r, ref);
	return 0;
}

static int check_peak(double v0, double v1, double vmax, double L, double a, double j)
{
	unsigned char buf[256];
	struct seg *g = (struct seg *)(void *)buf;

	memset(buf, 0, sizeof(buf));
	g->kind = SEG_MOVE;
	g->len = L;
	g->vmax = vmax;
	g->amax = a;
	g->jmax = j;
	double vp = plan_peak(g, v0, v1, true), ref = ref_peak(v0, v1, vmax, L, a, j);
	double vlo = v0 > v1 ? v0 : v1;

	CHECK(isfinite(vp) && vp >= vlo && vp <= vmax,
	      "peak(v0=%g v1=%g vmax=%g L=%g a=%g j=%g) = %g", v0, v1, vmax, L, a, j, vp);
	CHECK(vp == vlo || two(v0, vp, v1, a, j) <= L,
	      "peak(v0=%g v1=%g vmax=%g L=%g a=%g j=%g) = %.17g does not fit", v0, v1,
	      vmax, L, a, j, vp);
	CHECK(CLOSE(vp, ref), "peak(v0=%g v1=%g vmax=%g L=%g a=%g j=%g) = %.17g, bisection %.17g",
	      v0, v1, vmax, L, a, j, vp, ref);
	return 0;
}

static int t_reach_random(void)
{
	for (int i = 0; i < 200000; i++) {
		double a = lrand(10.0, 1e5), j = lrand(1e2, 1e9);
		double v = urand() < 0.1 ? 0.0 : lrand(1e-3, 2000.0);
		double L = lrand(1e-7, 1e3);
		if (check_reach(v, L, a, j))
			return 1;
	}
	return 0;
}

static int t_reach_edges(void)
{
	const double a = 5000.0, j = 1e6, c = a * a / j;

	CHECK(plan_reach(3.0, 0.0, a, j, true) == 3.0, "no length, no change");
	/* exactly at the boundary between the two kinds of transition */
	for (double v = 0.0; v <= 100.0; v += 25.0) {
		double Ls = (2.0 * v + c) * a / j;
		if (check_reach(v, Ls, a, j) || check_reach(v, Ls * (1 + 1e-12), a, j) ||
		    check_reach(v, Ls * (1 - 1e-12), a, j))
			return 1;
		double r = plan_reach(v, Ls, a, j, true);
		CHECK(fabs(r - (v + c)) <= 1e-9 * (v + c), "boundary: %.17g vs %.17g", r, v + c);
	}
	if (check_reach(0.0, 1e-12, a, j) || check_reach(1e4, 1e-9, a, j) ||
	    check_reach(0.0, 1e6, a, j))
		return 1;
	/* trapezoid mode is unchanged: the closed form */
	CHECK(plan_reach(2.0, 1.5, a, j, false) == sqrt(4.0 + 2.0 * a * 1.5), "trapezoid");
	return 0;
}

static int t_peak_random(void)
{
	for (int i = 0; i < 200000; i++) {
		double a = lrand(10.0, 1e5), j = lrand(1e2, 1e9);
		double vmax = lrand(1.0, 2000.0), L = lrand(1e-7, 1e3);
		double v0 = urand() < 0.2 ? 0.0 : urand() * vmax;
		double v1 = urand() < 0.2 ? 0.0 : urand() * vmax;
		/* as the look-ahead hands them over: v1 reachable from v0 */
		double r = v0 < v1 ? plan_reach(v0, L, a, j, true) : plan_reach(v1, L, a, j, true);
		if (v0 < v1 && v1 > r)
			v1 = r;
		else if (v1 < v0 && v0 > r)
			v0 = r;
		if (check_peak(v0, v1, vmax, L, a, j))
			return 1;
	}
	return 0;
}

/* Short segments between nearly equal speeds, as on the benchmark's arcs
 * (plan_peak's Newton in the smooth variable, peak_short()), and peaks
 * whose speed change is near a^2/j (where that path hands over to
 * fit_solve()). */
static int t_peak_short(void)
{
	for (int i = 0; i < 100000; i++) {
		double a = lrand(10.0, 1e5), j = lrand(1e2, 1e9), c = a * a / j;
		double u = lrand(1e-2, 500.0), e = urand() < 0.1 ? 0.0 : lrand(1e-9, 1e-1);
		double v0 = u * (1.0 - e), v1 = u * (1.0 + e);
		double L = urand() < 0.5 ? lrand(1e-8, 1e-3) :
			   /* a peak about c above the lower speed */
			   two(v0, v0 + c * lrand(0.5, 2.0), v1 > v0 + c ? v0 : v1, a, j);
		if (urand() < 0.5) {
			double t = v0;
			v0 = v1;
			v1 = t;
		}
		if (check_peak(v0, v1, lrand(1.0, 4.0) * (u * (1.0 + e) + c), L, a, j))
			return 1;
	}
	return 0;
}

static int t_peak_edges(void)
{
	const double a = 5000.0, j = 1e6;

	if (check_peak(0, 0, 100, 1e-9, a, j) || check_peak(0, 0, 100, 1e3, a, j) ||
	    check_peak(50, 50, 100, 1e-6, a, j) || check_peak(0, 99.9, 100, 10, a, j) ||
	    check_peak(100, 100, 100, 1e-3, a, j))
		return 1;
	/* entry and exit that do not fit: the larger of the two (the caller's
	 * look-ahead never hands this over; the answer is still defined) */
	unsigned char buf[256];
	struct seg *g = (struct seg *)(void *)buf;
	memset(buf, 0, sizeof(buf));
	g->kind = SEG_MOVE;
	g->len = 1e-9;
	g->vmax = 100;
	g->amax = a;
	g->jmax = j;
	CHECK(plan_peak(g, 0, 80, true) == 80, "infeasible pair: %g", plan_peak(g, 0, 80, true));
	return 0;
}

static const struct test_case cases[] = {
	{ "reach_random", t_reach_random },
	{ "reach_edges", t_reach_edges },
	{ "peak_random", t_peak_random },
	{ "peak_short", t_peak_short },
	{ "peak_edges", t_peak_edges },
};

int main(int argc, char **argv)
{
	return test_main(argc, argv, cases, sizeof(cases) / sizeof(cases[0]));
}
