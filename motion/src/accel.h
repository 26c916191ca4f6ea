/* SPDX-License-Identifier: MIT */
/*
 * The accel stage, between the profile lanes (peak.h: each segment's peak
 * speed, taken back here in planning order) and the interpolation lanes:
 * the timed profile of each segment from its three speeds (plan_profile())
 * and the serial part of interpolation (interp.h): the duration of the
 * profile, the time of its first sample (carried over from the previous
 * segment), the choice at a stop between going on and a sample at rest,
 * and the cut of the samples into chunks dealt to the interpolation lanes
 * in turn.
 */
#ifndef SERVOAMP_MOTION_ACCEL_H
#define SERVOAMP_MOTION_ACCEL_H

#include <stdatomic.h>
#include <stdbool.h>
#include <stdint.h>

#include "interp.h"
#include "motion/motion.h"
#include "motion/ring.h"
#include "peak.h"

struct accel {
	/* wiring, read-only after accel_init() */
	struct motion *m;         /* for pipeline_rest_now() */
	struct peaks *in;         /* struct planned, from the profile lanes */
	struct interp *ip;        /* the lanes (their input rings) */
	const struct ring *segs;  /* the segments the items refer to */
	uint32_t batch, lanes, chunk, na;
	double T;
	bool jerk;
	/* state: the current segment and the time into it */
	uint32_t seg;
	uint8_t kind;
	bool cur_valid;
	double v1, dur, tau;
	struct profile prof;      /* the current segment's */
	uint32_t lane, fill;      /* current lane, samples in its chunk */
	_Atomic uint64_t n_profiles;
	/* samples dealt to each lane (read by interp_levels()) */
	_Alignas(RING_CACHELINE) _Atomic uint64_t issued[INTERP_MAX_LANES];
};

void accel_init(struct accel *a, struct motion *m,
		const struct motion_config *cfg, struct peaks *in,
		struct interp *ip, const struct ring *segs);

/* Scheduler task (arg: struct accel). */
void accel_levels(void *arg, uint32_t *ul, uint32_t *dl, uint32_t *dcap);
uint32_t accel_run(void *arg, unsigned worker);

#endif
