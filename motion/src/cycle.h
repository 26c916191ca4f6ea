/* SPDX-License-Identifier: MIT */
/*
 * The consumer end of the pipeline: motion_next_setpoint() once per cycle
 * (or, in threaded mode, the periodic send task that calls it), and the
 * benchmark's sink task that drains the setpoints instead.
 */
#ifndef SERVOAMP_MOTION_CYCLE_H
#define SERVOAMP_MOTION_CYCLE_H

#include <stdatomic.h>
#include <stdbool.h>
#include <stdint.h>

#include "motion/motion.h"

struct consumer {
	struct motion_setpoint last; /* held when no new setpoint comes */
	uint64_t cycle;
	uint32_t lane; /* the interpolation lane of the next chunk */
	bool underrun;
	uint64_t sink_sum;
	_Atomic uint64_t n_setpoints, n_underruns;
};

/* Scheduler tasks (arg: struct motion). */
void sink_levels(void *arg, uint32_t *ul, uint32_t *dl, uint32_t *dcap);
uint32_t sink_run(void *arg, unsigned worker);
uint32_t send_run(void *arg, unsigned worker);

#endif
