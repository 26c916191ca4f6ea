/* SPDX-License-Identifier: MIT */
/* Geometry and limit tests of the whole pipeline (synchronous mode). */
#define _POSIX_C_SOURCE 200809L
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"

#define PI 3.14159265358979323846

static struct motion_config base(void)
{
	struct motion_config c;

	motion_config_default(&c);
	return c;
}

static struct motion_config fine(void)
{
	struct motion_config c = base();

	c.increments_per_mm = 1e6; /* 1 nm: quantisation far below limits */
	return c;
}

static int run_prog(const struct motion_config *c, const char *prog, struct trace *tr)
{
	if (run_program(c, prog, 64, 10000000, tr))
		return -1;
	return 0;
}

#define RUN_OK(cfg, prog, tr)                                                  \
	do {                                                                   \
		CHECK(run_prog(cfg, prog, tr) == 0, "could not create motion");    \
		CHECK((tr)->final == MOTION_ST_DONE, "final status %d, error: %s", \
		      (int)(tr)->final, (tr)->has_err ? (tr)->err.msg : "-");  \
	} while (0)

static int expect_end(const struct trace *tr, int32_t x, int32_t y, int32_t z)
{
	const struct motion_setpoint *e = &tr->sp[tr->n - 1];

	CHECK(e->pos[0] == x && e->pos[1] == y && e->pos[2] == z,
	      "end (%d,%d,%d) != expected (%d,%d,%d)", e->pos[0], e->pos[1],
	      e->pos[2], x, y, z);
	for (int k = 0; k < 3; k++)
		CHECK(e->vel[k] == 0, "velocity not zero at the end");
	return 0;
}

/* Radial deviation of the setpoints of source line `line` from a circle
 * (plane axes a0, a1); returns the max |r - R| in mm, and checks that
 * at least `min_pts` setpoints belong to it. */
static double radial_dev(const struct trace *tr, double ipm, uint32_t line,
			 unsigned a0, unsigned a1, double c0, double c1, double R,
			 size_t *npts)
{
	double worst = 0;

	*npts = 0;
	for (size_t i = 0; i < tr->n; i++) {
		if (tr->sp[i].line != line || tr->sp[i].status != MOTION_ST_MOVING)
			continue;
		double x = tr->sp[i].pos[a0] / ipm - c0;
		double y = tr->sp[i].pos[a1] / ipm - c1;
		double d = fabs(hypot(x, y) - R);
		if (d > worst)
			worst = d;
		(*npts)++;
	}
	return worst;
}

/* ---- geometry ------------------------------------------------------------ */

static int t_line_endpoint(void)
{
	struct motion_config c = base();
	struct trace tr;

	RUN_OK(&c, "G21 G90\nG1 X10.001 Y-3.5 Z2 F3000\nM2\n", &tr);
	if (expect_end(&tr, 10001, -3500, 2000))
		return 1;
	/* every point on the segment from the origin */
	for (size_t i = 0; i < tr.n; i++) {
		double x = tr.sp[i].pos[0], y = tr.sp[i].pos[1], z = tr.sp[i].pos[2];
		double L = sqrt(10001.0 * 10001 + 3500.0 * 3500 + 2000.0 * 2000);
		double t = (x * 10001 - y * 3500 + z * 2000) / (L * L);
		double dx = x - t * 10001, dy = y + t * 3500, dz = z - t * 2000;
		CHECK(sqrt(dx * dx + dy * dy + dz * dz) <= 1.0,
		      "point %zu off the line", i);
		CHECK(t >= -1e-9 && t <= 1 + 1e-9, "point %zu beyond the segment", i);
	}
	trace_free(&tr);
	return 0;
}

static int t_arc_centre_form(void)
{
	struct motion_config c = fine();
	struct trace tr;
	size_t n;

	c.chord_tol = 0.002;
	RUN_OK(&c, "G17 G2 X10 Y0 I5 J0 F1200\nM30\n", &tr);
	if (expect_end(&tr, 10000000, 0, 0))
		return 1;
	double dev = radial_dev(&tr, c.increments_per_mm, 1, 0, 1, 5, 0, 5, &n);
	CHECK(n > 100, "only %zu points on the arc", n);
	CHECK(dev <= c.chord_tol + 1e-6, "radial deviation %.6f > tol %.6f", dev,
	      c.chord_tol);
	/* clockwise from (0,0) to (10,0) around (5,0) goes through y > 0 */
	double ymax = 0;
	for (size_t i = 0; i < tr.n; i++) {
		double y = tr.sp[i].pos[1] / c.increments_per_mm;
		CHECK(y >= -1e-6, "G2 went below the chord (y = %f)", y);
		if (y > ymax)
			ymax = y;
	}
	CHECK(fabs(ymax - 5) < c.chord_tol + 1e-3, "top of arc %.6f != 5", ymax);
	trace_free(&tr);
	return 0;
}

static int t_arc_chord_tolerance_used(void)
{
	/* a coarse tolerance must give a visibly polygonal arc (the test
	 * measures the chord error, so it can fail both ways) */
	struct motion_config c = fine();
	struct trace tr;
	size_t n;

	c.chord_tol = 0.05;
	RUN_OK(&c, "G3 X10 I5 F600\n", &tr);
	double dev = radial_dev(&tr, c.increments_per_mm, 1, 0, 1, 5, 0, 5, &n);
	CHECK(dev <= c.chord_tol + 1e-6, "deviation %.6f > tol", dev);
	CHECK(dev >= 0.2 * c.chord_tol, "deviation %.6f: chords much finer than asked", dev);
	trace_free(&tr);
	return 0;
}

static int t_arc_radius_form(void)
{
	struct motion_config c = fine();
	struct trace tr;
	size_t n;

	/* minor arc: centre (0,10) */
	RUN_OK(&c, "G3 X10 Y10 R10 F1200\n", &tr);
	if (expect_end(&tr, 10000000, 10000000, 0))
		return 1;
	double dev = radial_dev(&tr, c.increments_per_mm, 1, 0, 1, 0, 10, 10, &n);
	CHECK(n > 10 && dev <= c.chord_tol + 1e-6, "minor arc deviation %.6f", dev);
	trace_free(&tr);
	/* major arc (R < 0): centre (10,0), passes x < 0... no: y < 0 */
	RUN_OK(&c, "G3 X10 Y10 R-10 F1200\n", &tr);
	dev = radial_dev(&tr, c.increments_per_mm, 1, 0, 1, 10, 0, 10, &n);
	CHECK(n > 10 && dev <= c.chord_tol + 1e-6, "major arc deviation %.6f", dev);
	double ymin = 0;
	for (size_t i = 0; i < tr.n; i++)
		if (tr.sp[i].pos[1] / c.increments_per_mm < ymin)
			ymin = tr.sp[i].pos[1] / c.increments_per_mm;
	CHECK(fabs(ymin + 10) < 1e-3, "major arc lowest y %.6f != -10", ymin);
	trace_free(&tr);
	return 0;
}

static int t_full_circle(void)
{
	struct motion_config c = fine();
	struct trace tr;
	size_t n;

	RUN_OK(&c, "G1 X1 F3000\nG2 I5 F1500\nG0 X0\n", &tr);
	if (expect_end(&tr, 0, 0, 0))
		return 1;
	double dev = radial_dev(&tr, c.increments_per_mm, 2, 0, 1, 6, 0, 5, &n);
	CHECK(n > 100 && dev <= c.chord_tol + 1e-6, "circle deviation %.6f", dev);
	double xmax = 0, ymin = 0, ymax = 0;
	for (size_t i = 0; i < tr.n; i++) {
		if (tr.sp[i].line != 2)
			continue;
		double x = tr.sp[i].pos[0] / c.increments_per_mm;
		double y = tr.sp[i].pos[1] / c.increments_per_mm;
		xmax = x > xmax ? x : xmax;
		ymin = y < ymin ? y : ymin;
		ymax = y > ymax ? y : ymax;
	}
	CHECK(fabs(xmax - 11) < 2e-3 && fabs(ymin + 5) < 2e-3 && fabs(ymax - 5) < 2e-3,
	      "circle extent x<=%f y in [%f,%f]", xmax, ymin, ymax);
	/* path length of the circle vs 2*pi*5 */
	double len = 0;
	for (size_t i = 1; i < tr.n; i++) {
		if (tr.sp[i].line != 2 || tr.sp[i - 1].line != 2)
			continue;
		double dx = (tr.sp[i].pos[0] - tr.sp[i - 1].pos[0]) / c.increments_per_mm;
		double dy = (tr.sp[i].pos[1] - tr.sp[i - 1].pos[1]) / c.increments_per_mm;
		len += hypot(dx, dy);
	}
	CHECK(fabs(len - 2 * PI * 5) < 0.01, "circle length %.5f", len);
	trace_free(&tr);
	return 0;
}

static int t_helix(void)
{
	struct motion_config c = fine();
	struct trace tr;
	size_t n;

	RUN_OK(&c, "G17 G3 X0 Y0 Z5 I5 J0 P2 F1200\n", &tr);
	if (expect_end(&tr, 0, 0, 5000000))
		return 1;
	double dev = radial_dev(&tr, c.increments_per_mm, 1, 0, 1, 5, 0, 5, &n);
	CHECK(n > 100 && dev <= c.chord_tol + 1e-6, "helix radial deviation %.6f", dev);
	/* z rises monotonically, in proportion to the swept angle */
	double acc = 0, prev = PI;
	for (size_t i = 1; i < tr.n; i++) {
		CHECK(tr.sp[i].pos[2] >= tr.sp[i - 1].pos[2], "z went down at %zu", i);
		double x = tr.sp[i].pos[0] / c.increments_per_mm - 5;
		double y = tr.sp[i].pos[1] / c.increments_per_mm;
		double th = atan2(y, x), d = th - prev;
		while (d < -PI)
			d += 2 * PI;
		while (d > PI)
			d -= 2 * PI;
		acc += d;
		prev = th;
		double z = tr.sp[i].pos[2] / c.increments_per_mm;
		CHECK(fabs(z - 5 * acc / (4 * PI)) < 0.01, "z %.5f vs angle %.5f", z, acc);
	}
	CHECK(fabs(acc - 4 * PI) < 1e-3, "helix swept %.5f rad, not 4 pi", acc);
	trace_free(&tr);
	return 0;
}

static int t_planes(void)
{
	struct motion_config c = fine();
	struct trace tr;
	size_t n;

	/* G18: ZX plane; G2 seen from +Y is clockwise, so it passes z < 0 */
	RUN_OK(&c, "G18 G2 X10 Z0 I5 K0 F1200\n", &tr);
	if (expect_end(&tr, 10000000, 0, 0))
		return 1;
	double dev = radial_dev(&tr, c.increments_per_mm, 1, 2, 0, 0, 5, 5, &n);
	CHECK(n > 10 && dev <= c.chord_tol + 1e-6, "G18 deviation %.6f", dev);
	for (size_t i = 0; i < tr.n; i++) {
		CHECK(tr.sp[i].pos[1] == 0, "G18 arc moved Y");
		CHECK(tr.sp[i].pos[2] <= 1, "G18 G2 passed z > 0 at %zu", i);
	}
	trace_free(&tr);
	/* G19: YZ plane; G3 seen from +X is counter-clockwise: from
	 * (y=0,z=0) around (y=5,z=0) to (y=10,z=0) passes z < 0 */
	RUN_OK(&c, "G19 G3 Y10 Z0 J5 K0 F1200\n", &tr);
	if (expect_end(&tr, 0, 10000000, 0))
		return 1;
	dev = radial_dev(&tr, c.increments_per_mm, 1, 1, 2, 5, 0, 5, &n);
	CHECK(n > 10 && dev <= c.chord_tol + 1e-6, "G19 deviation %.6f", dev);
	for (size_t i = 0; i < tr.n; i++) {
		CHECK(tr.sp[i].pos[0] == 0, "G19 arc moved X");
		CHECK(tr.sp[i].pos[2] <= 1, "G19 G3 passed z > 0 at %zu", i);
	}
	trace_free(&tr);
	return 0;
}

static int t_units_and_modes(void)
{
	struct motion_config c = base();
	struct trace tr;

	RUN_OK(&c, "G20 G1 X1 Y0.5 F20\nM2\n", &tr);
	if (expect_end(&tr, 25400, 12700, 0))
		return 1;
	trace_free(&tr);
	RUN_OK(&c, "G21 G91 G1 X1 F600\nX1\nX1\nY-2.5\nG90 X2\n", &tr);
	if (expect_end(&tr, 2000, -2500, 0))
		return 1;
	trace_free(&tr);
	/* G92 shifts the program origin; G92.1 cancels it */
	RUN_OK(&c, "G1 X2 F600\nG92 X0\nG1 X1\nG92.1\nG1 Y1\n", &tr);
	if (expect_end(&tr, 3000, 1000, 0))
		return 1;
	trace_free(&tr);
	RUN_OK(&c, "G1 X2 F600\nG92 X0\nG1 X1\nG92.1\nG1 X1\n", &tr);
	if (expect_end(&tr, 1000, 0, 0))
		return 1;
	trace_free(&tr);
	/* inch mode with incremental arcs: I is an offset in inches */
	RUN_OK(&c, "G20 G91 G2 X0.2 Y0 I0.1 J0 F10\n", &tr);
	if (expect_end(&tr, 5080, 0, 0))
		return 1;
	trace_free(&tr);
	/* comments, line numbers, lower case, % */
	RUN_OK(&c, "%\nN10 g1 x1.5 (comment) f600 ; trailing\nN20 (only a comment)\n%\n", &tr);
	if (expect_end(&tr, 1500, 0, 0))
		return 1;
	trace_free(&tr);
	return 0;
}

static int t_rapid_reaches_speed(void)
{
	struct motion_config c = fine();
	struct trace tr;
	struct measured m;

	c.axis[0].vmax = 150;
	RUN_OK(&c, "G0 X200\n", &tr);
	measure(&tr, c.period_us * 1e-6, c.increments_per_mm, &m);
	CHECK(m.v[0] >= 0.99 * 150 && m.v[0] <= 150 * (1 + 1e-6) + 1e-3,
	      "rapid peak %.4f, axis limit 150", m.v[0]);
	trace_free(&tr);
	return 0;
}

static int t_dwell(void)
{
	struct motion_config c = base();
	struct trace tr;
	size_t run = 0, best = 0;

	RUN_OK(&c, "G1 X1 F600\nG4 P0.25\nG1 X2\n", &tr);
	for (size_t i = 1; i < tr.n; i++) {
		if (tr.sp[i].pos[0] == 1000 && tr.sp[i - 1].pos[0] == 1000)
			run++;
		else
			run = 0;
		best = run > best ? run : best;
	}
	CHECK(best >= 249 && best <= 253, "held X1 for %zu cycles, want ~250", best);
	trace_free(&tr);
	return 0;
}

/* ---- limits ----------------------------------------------------------------- */

static int limits_ok(const struct motion_config *c, const char *prog)
{
	struct trace tr;
	char why[200];

	RUN_OK(c, prog, &tr);
	int r = check_limits(&tr, c, why, sizeof(why));
	CHECK(r == 0, "%s", why);
	trace_free(&tr);
	return 0;
}

static char *gen_mixed(unsigned seed, int n)
{
	size_t cap = (size_t)n * 80 + 64, len = 0;
	char *p = malloc(cap);
	double x = 0, y = 0, z = 0;
	uint32_t s = seed;

	if (!p)
		return NULL;
#define RND() ((s = s * 1664525u + 1013904223u) >> 8)
	for (int i = 0; i < n; i++) {
		unsigned kind = RND() % 6;
		double nx = x + (double)(RND() % 2001) / 100.0 - 10.0;
		double ny = y + (double)(RND() % 2001) / 100.0 - 10.0;
		double nz = z + (double)(RND() % 201) / 100.0 - 1.0;
		nx = fmax(-100, fmin(100, nx));
		ny = fmax(-100, fmin(100, ny));
		nz = fmax(-10, fmin(10, nz));
		unsigned feed = 300 + RND() % 9000;
		if (kind == 0) {
			len += (size_t)snprintf(p + len, cap - len, "G0 X%.3f Y%.3f Z%.3f\n", nx, ny, nz);
		} else if (kind <= 2) {
			len += (size_t)snprintf(p + len, cap - len, "G1 X%.3f Y%.3f F%u\n", nx, ny, feed);
			nz = z;
		} else if (kind == 3) { /* many small collinear-ish steps */
			len += (size_t)snprintf(p + len, cap - len, "G1 X%.3f Y%.3f Z%.3f F%u\n",
						x + 0.05, y + 0.02, z, feed);
			nx = x + 0.05; ny = y + 0.02; nz = z;
		} else {
			double r = 1 + (double)(RND() % 1000) / 100.0;
			double d = hypot(nx - x, ny - y);
			if (d < 0.01 || d > 2 * r) {
				nx = x; ny = y; nz = z;
				continue;
			}
			len += (size_t)snprintf(p + len, cap - len, "G%d X%.3f Y%.3f Z%.3f R%.3f F%u\n",
						kind == 4 ? 2 : 3, nx, ny, nz, (RND() & 1) ? r : -r, feed);
		}
		x = nx; y = ny; z = nz;
	}
#undef RND
	return p;
}

static int t_limits_square(void)
{
	struct motion_config c = fine();
	struct trace tr;
	struct measured m;
	char why[200];

	RUN_OK(&c, "G1 X50 F6000\nY50\nX0\nY0\n", &tr);
	CHECK(check_limits(&tr, &c, why, sizeof(why)) == 0, "%s", why);
	measure(&tr, c.period_us * 1e-6, c.increments_per_mm, &m);
	CHECK(m.v[0] > 0.99 * 100 && m.v[1] > 0.99 * 100,
	      "edges did not reach the feed: %.3f %.3f mm/s", m.v[0], m.v[1]);
	CHECK(m.a[0] > 0.4 * c.axis[0].amax, "acceleration unused: %.1f", m.a[0]);
	trace_free(&tr);
	return 0;
}

static int t_limits_mixed(void)
{
	struct motion_config c = fine();
	char *p = gen_mixed(12345, 300);
	int r;

	CHECK(p, "oom");
	r = limits_ok(&c, p);
	free(p);
	return r;
}

static int t_limits_per_axis(void)
{
	struct motion_config c = fine();
	char *p = gen_mixed(777, 200);
	int r;

	CHECK(p, "oom");
	c.axis[0].vmax = 300; c.axis[0].amax = 5000;
	c.axis[1].vmax = 40;  c.axis[1].amax = 300;
	c.axis[2].vmax = 10;  c.axis[2].amax = 100;
	c.period_us = 2000; /* the scheduler's design ran at 2 ms */
	r = limits_ok(&c, p);
	free(p);
	return r;
}

static int t_limits_jerk(void)
{
	struct motion_config c = fine();
	char *p = gen_mixed(4242, 120);
	int r;

	CHECK(p, "oom");
	c.jerk_limited = true;
	for (int k = 0; k < 3; k++)
		c.axis[k].jmax = 50000;
	r = limits_ok(&c, p);
	free(p);
	return r;
}

static int t_jerk_profile_smooth(void)
{
	/* on a single straight move, jerk-limited acceleration ramps: the
	 * measured jerk is within the limit and much below the trapezoid's */
	struct motion_config c = fine();
	struct trace tr;
	struct measured mt, mj;

	RUN_OK(&c, "G1 X40 F6000\n", &tr);
	measure(&tr, c.period_us * 1e-6, c.increments_per_mm, &mt);
	trace_free(&tr);
	c.jerk_limited = true;
	c.axis[0].jmax = 20000;
	RUN_OK(&c, "G1 X40 F6000\n", &tr);
	measure(&tr, c.period_us * 1e-6, c.increments_per_mm, &mj);
	char why[200];
	CHECK(check_limits(&tr, &c, why, sizeof(why)) == 0, "%s", why);
	CHECK(mj.j[0] < 0.2 * mt.j[0], "jerk %.0f (S-curve) vs %.0f (trapezoid)", mj.j[0], mt.j[0]);
	CHECK(mj.a[0] > 0.3 * c.axis[0].amax, "S-curve never accelerated: %.1f", mj.a[0]);
	trace_free(&tr);
	return 0;
}

static int t_velocity_continuity(void)
{
	/* 40 collinear 1 mm segments: the look-ahead keeps the speed up
	 * across the junctions (no stop at each block) */
	struct motion_config c = fine();
	struct trace tr;
	char prog[2048];
	size_t len = 0;

	for (int i = 1; i <= 40; i++)
		len += (size_t)snprintf(prog + len, sizeof(prog) - len, "G1 X%d F3000\n", i);
	RUN_OK(&c, prog, &tr);
	double T = c.period_us * 1e-6;
	size_t slow = 0;
	for (size_t i = 1; i < tr.n; i++) {
		double x = tr.sp[i].pos[0] / c.increments_per_mm;
		double v = (tr.sp[i].pos[0] - tr.sp[i - 1].pos[0]) / c.increments_per_mm / T;
		if (x > 5 && x < 35 && v < 0.99 * 50)
			slow++;
	}
	CHECK(slow == 0, "%zu cycles below the feed in the middle of the line", slow);
	trace_free(&tr);
	/* a right-angle corner must nearly stop */
	RUN_OK(&c, "G1 X20 F6000\nY20\n", &tr);
	double vmin = 1e9;
	for (size_t i = 1; i < tr.n; i++) {
		double dx = (tr.sp[i].pos[0] - tr.sp[i - 1].pos[0]) / c.increments_per_mm;
		double dy = (tr.sp[i].pos[1] - tr.sp[i - 1].pos[1]) / c.increments_per_mm;
		double x = tr.sp[i].pos[0] / c.increments_per_mm;
		double y = tr.sp[i].pos[1] / c.increments_per_mm;
		if (x > 19.5 && y < 0.5)
			vmin = fmin(vmin, hypot(dx, dy) / T);
	}
	/* junction speed share*amax*T, plus one cycle of deceleration as
	 * the sampled speed is a mean over the cycle */
	CHECK(vmin <= c.axis[0].amax * T + 1e-3, "corner speed %.4f too high", vmin);
	trace_free(&tr);
	return 0;
}

static int t_limits_tiny_segments(void)
{
	/* 0.01 mm segments at a high feed: every segment lasts >= 1 cycle */
	struct motion_config c = fine();
	size_t cap = 400 * 40, len = 0;
	char *p = malloc(cap);
	int r;

	CHECK(p, "oom");
	for (int i = 1; i <= 400; i++)
		len += (size_t)snprintf(p + len, cap - len, "G1 X%.3f Y%.3f F12000\n",
					i * 0.01, 0.5 * sin(i * 0.05));
	r = limits_ok(&c, p);
	free(p);
	return r;
}

static int t_limits_polyline_circle(void)
{
	/* a 1 mm radius circle as 0.01 mm G1 segments at 100 mm/s: each
	 * junction alone is harmless, but several of them inside one cycle
	 * would add up (the planner keeps every segment >= one cycle) */
	struct motion_config c = fine();
	size_t cap = 700 * 40, len = 0;
	char *p = malloc(cap);
	int r;

	CHECK(p, "oom");
	c.lookahead = 1024; /* long enough not to be the limit */
	len += (size_t)snprintf(p, cap, "G1 X1 F6000\n");
	for (int i = 1; i <= 628; i++)
		len += (size_t)snprintf(p + len, cap - len, "X%.5f Y%.5f\n", cos(i * 0.01),
					sin(i * 0.01));
	r = limits_ok(&c, p);
	free(p);
	if (r)
		return r;
	/* the same with a real arc and a very fine chord tolerance */
	c.chord_tol = 1e-6;
	return limits_ok(&c, "G1 X1 F6000\nG3 I-1\n");
}

static const struct test_case cases[] = {
	{ "line_endpoint", t_line_endpoint },
	{ "arc_centre_form", t_arc_centre_form },
	{ "arc_chord_tolerance_used", t_arc_chord_tolerance_used },
	{ "arc_radius_form", t_arc_radius_form },
	{ "full_circle", t_full_circle },
	{ "helix", t_helix },
	{ "planes", t_planes },
	{ "units_and_modes", t_units_and_modes },
	{ "rapid_reaches_speed", t_rapid_reaches_speed },
	{ "dwell", t_dwell },
	{ "limits_square", t_limits_square },
	{ "limits_mixed", t_limits_mixed },
	{ "limits_per_axis", t_limits_per_axis },
	{ "limits_jerk", t_limits_jerk },
	{ "jerk_profile_smooth", t_jerk_profile_smooth },
	{ "velocity_continuity", t_velocity_continuity },
	{ "limits_tiny_segments", t_limits_tiny_segments },
	{ "limits_polyline_circle", t_limits_polyline_circle },
};

int main(int argc, char **argv)
{
	return test_main(argc, argv, cases, sizeof(cases) / sizeof(cases[0]));
}
