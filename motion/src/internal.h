/* SPDX-License-Identifier: MIT */
/* Internal data items of the pipeline and the planner math. */
#ifndef SERVOAMP_MOTION_INTERNAL_H
#define SERVOAMP_MOTION_INTERNAL_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "motion/motion.h"

enum seg_kind { SEG_MOVE = 1, SEG_DWELL, SEG_END };

/* A straight segment (output of curve fitting), sized by the number of
 * axes: x[] holds p0[n], p1[n] and u[n] (n = config.n_axes; the other
 * axes never move, so they are not stored).  A segment is written once,
 * by the fitter, into a slot of the segment ring, and the later stages
 * refer to that slot by its index instead of copying the geometry along
 * the chain: the ring's storage is larger than its capacity (see
 * motion_create), so a slot is not reused before interpolation is done
 * with it. */
struct seg {
	uint8_t kind;
	uint32_t line;
	double len;   /* mm */
	double vmax;  /* path speed cap: feed, axis velocities, len / period */
	double amax;  /* path acceleration: (1 - share) of the axis budgets */
	double jmax;  /* path jerk (jerk-limited mode) */
	double dwell; /* s */
	double x[];   /* p0[n], p1[n], u[n] */
};

#define SEG_P0(s, n) ((s)->x)
#define SEG_P1(s, n) ((s)->x + (n))
#define SEG_U(s, n) ((s)->x + 2 * (n))

static inline size_t seg_size(uint32_t n_axes)
{
	return sizeof(struct seg) + 3u * n_axes * sizeof(double);
}

/* A segment with its planned entry and exit speeds (look-ahead output):
 * the segment by reference (slot index in the segment ring). */
struct planned {
	uint32_t seg;
	uint8_t kind;
	double v0, v1;
};

/* One speed transition va -> va + sigma * dv: jerk phase tj, constant
 * acceleration phase ta, peak acceleration A (tj = 0 for trapezoids). */
struct trans {
	double va, sigma, A, j, tj, ta;
};

/* Accel-planning output: the segment (by reference) with its entry, peak
 * and exit speeds, 32 bytes.  Finding the peak speed is the planning
 * (a bisection in jerk-limited mode); the interpolator expands the timed
 * profile below from these three speeds when it takes the segment, so
 * that only 32 bytes per segment travel between the two stages. */
struct timed {
	uint32_t seg;
	uint8_t kind;
	double v0, vp, v1;
};

/* A timed velocity profile over one segment (the interpolator's current
 * segment).  The transitions are stored compactly; their start speeds are
 * v0 and vp, their jerk is j. */
struct profile {
	uint8_t kind;
	int8_t sg1, sg3;        /* signs of the two transitions */
	double v0, vp, v1;
	double t1, t2, dur;     /* transition, cruise; total duration */
	double d1, d2;          /* distance at the end of phases 1 and 2 */
	double j;               /* path jerk (both transitions) */
	double A1, tj1, ta1;    /* transition 1: v0 -> vp */
	double A3, tj3, ta3;    /* transition 3: vp -> v1 */
};

struct plan_params {
	bool jerk;
};

/* Time and distance of a transition between two speeds. */
double plan_trans_time(double dv, double a, double j, bool jerk);
double plan_trans_dist(double va, double vb, double a, double j, bool jerk);
/* Largest speed reachable from v (up or down, symmetric) within L. */
double plan_reach(double v, double L, double a, double j, bool jerk);
/* Peak speed of a move from v0 to v1 (accel planning). */
double plan_peak(const struct seg *g, double v0, double v1, bool jerk);
/* The timed profile of a segment with the speeds plan_peak() chose. */
void plan_profile(struct profile *p, const struct seg *g, double v0, double vp,
		  double v1, bool jerk);
/* Path position and speed at time t; len is the segment's length. */
void plan_eval(const struct profile *p, double len, double t, double *s, double *v);

#endif
