/* SPDX-License-Identifier: MIT */
/*
 * The interpolation stage: expands each segment's timed profile (plan.h)
 * and samples it once per period into compact setpoints (items.h).  A
 * sample left over at the end of a segment carries into the next one; at
 * rest it emits one sample exactly at the end point.
 */
#ifndef SERVOAMP_MOTION_INTERP_H
#define SERVOAMP_MOTION_INTERP_H

#include <stdatomic.h>
#include <stdbool.h>
#include <stdint.h>

#include "motion/motion.h"
#include "motion/ring.h"
#include "plan.h"

struct interp {
	/* wiring, read-only after interp_init() */
	struct motion *m;         /* for pipeline_notify_end() */
	struct ring *in;          /* struct timed */
	struct ring *out;         /* compact setpoints */
	const struct ring *segs;  /* the segments the items refer to */
	uint32_t na, batch;
	double T;                 /* period, s */
	double ipm;               /* increments per mm */
	bool jerk;
	/* state: the current segment and the time into it */
	struct profile cur;
	const struct seg *cur_g;  /* cur's segment (in the segment ring) */
	bool cur_valid;
	double tau, tau_start;
	atomic_bool moving, done;
};

void interp_init(struct interp *ip, struct motion *m,
		 const struct motion_config *cfg, struct ring *in,
		 struct ring *out, const struct ring *segs);

/* Scheduler task (arg: struct interp). */
void interp_levels(void *arg, uint32_t *ul, uint32_t *dl, uint32_t *dcap);
uint32_t interp_run(void *arg, unsigned worker);

#endif
