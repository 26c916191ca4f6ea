/* SPDX-License-Identifier: MIT */
/* The planner math: speed transitions, reachable and peak speeds of a
 * segment, and its timed velocity profile (trapezoid or S-curve). */
#ifndef SERVOAMP_MOTION_PLAN_H
#define SERVOAMP_MOTION_PLAN_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "items.h"

/* One speed transition va -> va + sigma * dv: jerk phase tj, constant
 * acceleration phase ta, peak acceleration A (tj = 0 for trapezoids). */
struct trans {
	double va, sigma, A, j, tj, ta;
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
