/* SPDX-License-Identifier: MIT */
/*
 * The look-ahead stage: a window of the next segments (by their slot in
 * the segment ring) with the junction speed limit between each two and a
 * backward pass that raises entry speeds as far as the segments ahead can
 * still stop; the oldest segment leaves with its entry and exit speeds
 * (struct planned, dealt to the profile lanes: peak.h) when the window is
 * full, at the end of the program, or when the pipeline is starving
 * (pipeline_starving()).
 */
#ifndef SERVOAMP_MOTION_LOOKAHEAD_H
#define SERVOAMP_MOTION_LOOKAHEAD_H

#include <stdbool.h>
#include <stdint.h>

#include "motion/motion.h"
#include "motion/ring.h"
#include "peak.h"

struct lookahead {
	/* wiring, read-only after lookahead_init() */
	const struct motion_config *cfg;
	const struct motion *m; /* for pipeline_starving() */
	struct ring *in;    /* struct seg */
	struct peaks *out;  /* struct planned, to the profile lanes */
	uint32_t na;
	double T;
	/* the window: segment-ring positions of the segments, their
	 * backward-pass entry speeds and junction limits */
	uint32_t *win;
	double *bwd, *jl;
	uint32_t head, n, W;
	double fixed;       /* exit speed of the last segment emitted */
	bool prev_move, flushing;
	double prev_u[MOTION_MAX_AXES];
	double prev_vmax;
};

/* Setup (allocates the window); 0 or -1. */
int lookahead_init(struct lookahead *la, const struct motion *m,
		   const struct motion_config *cfg, struct ring *in,
		   struct peaks *out);
void lookahead_free(struct lookahead *la);

/* Scheduler task (arg: struct lookahead). */
void lookahead_levels(void *arg, uint32_t *ul, uint32_t *dl, uint32_t *dcap);
uint32_t lookahead_run(void *arg, unsigned worker);

#endif
