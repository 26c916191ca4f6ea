/* SPDX-License-Identifier: MIT */
/*
 * The accel stage: the peak speed of each planned segment, between its
 * entry and exit speeds (plan_peak(): closed form for trapezoids, a
 * bracketed Newton iteration for S-curves).
 */
#ifndef SERVOAMP_MOTION_ACCEL_H
#define SERVOAMP_MOTION_ACCEL_H

#include <stdatomic.h>
#include <stdbool.h>
#include <stdint.h>

#include "motion/motion.h"
#include "motion/ring.h"

struct accel {
	/* wiring, read-only after accel_init() */
	struct ring *in;          /* struct planned */
	struct ring *out;         /* struct timed */
	const struct ring *segs;  /* the segments the items refer to */
	uint32_t batch;
	bool jerk;
	/* state */
	_Atomic uint64_t n_profiles;
};

void accel_init(struct accel *a, const struct motion_config *cfg,
		struct ring *in, struct ring *out, const struct ring *segs);

/* Scheduler task (arg: struct accel). */
void accel_levels(void *arg, uint32_t *ul, uint32_t *dl, uint32_t *dcap);
uint32_t accel_run(void *arg, unsigned worker);

#endif
