/* SPDX-License-Identifier: MIT */
/* Internal data items of the pipeline and the planner math. */
#ifndef SERVOAMP_MOTION_INTERNAL_H
#define SERVOAMP_MOTION_INTERNAL_H

#include <stdbool.h>
#include <stdint.h>

#include "motion/motion.h"

enum seg_kind { SEG_MOVE = 1, SEG_DWELL, SEG_END };

/* A straight segment (output of curve fitting). */
struct seg {
	uint8_t kind;
	uint32_t line;
	double p0[MOTION_MAX_AXES], p1[MOTION_MAX_AXES], u[MOTION_MAX_AXES];
	double len;   /* mm */
	double vmax;  /* path speed cap: feed, axis velocities, len / period */
	double amax;  /* path acceleration: (1 - share) of the axis budgets */
	double jmax;  /* path jerk (jerk-limited mode) */
	double dwell; /* s */
};

/* A segment with its planned entry and exit speeds (look-ahead output). */
struct planned {
	struct seg s;
	double v0, v1;
};

/* One speed transition va -> va + sigma * dv: jerk phase tj, constant
 * acceleration phase ta, peak acceleration A (tj = 0 for trapezoids). */
struct trans {
	double va, sigma, A, j, tj, ta;
};

/* A timed velocity profile over one segment (accel-planning output). */
struct profile {
	struct seg s;
	double v0, vp, v1;
	double t1, t2, t3, dur; /* transition, cruise, transition */
	double d1, d2;          /* distance at the end of phases 1 and 2 */
	struct trans tr1, tr3;
};

struct plan_params {
	bool jerk;
};

/* Time and distance of a transition between two speeds. */
double plan_trans_time(double dv, double a, double j, bool jerk);
double plan_trans_dist(double va, double vb, double a, double j, bool jerk);
/* Largest speed reachable from v (up or down, symmetric) within L. */
double plan_reach(double v, double L, double a, double j, bool jerk);
void plan_profile(struct profile *p, const struct planned *in, bool jerk);
void plan_eval(const struct profile *p, double t, double *s, double *v);

#endif
