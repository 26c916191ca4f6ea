/* SPDX-License-Identifier: MIT */
/*
 * The fit stage: G-code blocks into straight segments.  A line is one
 * segment, an arc (or helix) as many chords as the chord tolerance asks
 * for; each segment gets its speed, acceleration and jerk caps from the
 * axis limits.
 */
#ifndef SERVOAMP_MOTION_FIT_H
#define SERVOAMP_MOTION_FIT_H

#include <stdatomic.h>
#include <stdint.h>

#include "gcode.h"
#include "motion/motion.h"
#include "motion/ring.h"

struct fit {
	/* wiring, read-only after fit_init() */
	const struct motion_config *cfg;
	struct ring *in;    /* struct gc_block */
	struct ring *out;   /* struct seg */
	uint32_t na;        /* axes */
	double T;           /* period, s */
	/* state: the block being cut, k of n segments done */
	struct gc_block blk;
	atomic_bool have;
	atomic_bool busy;
	uint32_t k, n;
	double prev[MOTION_MAX_AXES];
	_Atomic uint64_t n_segs;
};

void fit_init(struct fit *f, const struct motion_config *cfg, struct ring *in,
	      struct ring *out);

/* Scheduler task (arg: struct fit). */
void fit_levels(void *arg, uint32_t *ul, uint32_t *dl, uint32_t *dcap);
uint32_t fit_run(void *arg, unsigned worker);

#endif
