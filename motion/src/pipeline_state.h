/* SPDX-License-Identifier: MIT */
/*
 * struct motion: the pipeline's context, made of one struct per stage
 * (stream.h, decode.h, fit.h, lookahead.h, peak.h, accel.h, interp.h,
 * cycle.h)
 * and the rings between them.  Only the pipeline's own files (pipeline.c,
 * cycle.c) see inside it; a stage sees its own struct and, through
 * pipeline.h, an opaque handle.
 */
#ifndef SERVOAMP_MOTION_PIPELINE_STATE_H
#define SERVOAMP_MOTION_PIPELINE_STATE_H

#include <pthread.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdint.h>

#include "accel.h"
#include "cycle.h"
#include "decode.h"
#include "fit.h"
#include "interp.h"
#include "lookahead.h"
#include "motion/motion.h"
#include "motion/ring.h"
#include "peak.h"
#include "pipeline.h"
#include "scheduler.h"
#include "stream.h"

#define CL RING_CACHELINE

/* The first fault of the run. */
struct fault {
	atomic_bool on;
	struct motion_error err;
	pthread_mutex_t lock;
};

/* motion_wait() callers, woken by pipeline_notify_end(). */
struct end_wait {
	pthread_mutex_t lock;
	pthread_cond_t cond;
	atomic_int waiters;
};

/* Each stage's state starts on its own cache line: in threaded mode the
 * stages run on different cores at the same time, and a write by one
 * stage must not invalidate the line another stage is reading.  The
 * counters of a stage are added once per job, not once per item. */
struct motion {
	/* read-mostly */
	struct motion_config cfg;
	uint32_t na; /* axes (config.n_axes): items are sized by it */
	double ipm;  /* increments per mm */
	struct sched *sched;
	bool threaded;
	bool loaded; /* an input was chosen (stream written or program) */
	struct stream src;
	struct ring q[MOTION_N_QUEUES]; /* q[Q_STREAM] unused (the stream) */

	_Alignas(CL) struct fault fault;
	_Alignas(CL) struct decode dec;
	_Alignas(CL) struct fit fit;
	_Alignas(CL) struct lookahead la;
	_Alignas(CL) struct peaks pk;
	_Alignas(CL) struct accel acc;
	_Alignas(CL) struct interp ip;
	_Alignas(CL) struct consumer out; /* motion_next_setpoint or the sink */
	_Alignas(CL) struct end_wait end; /* the end of the run */
};

/* Threaded mode: tell the worker pool that input or room changed. */
static inline void pipeline_kick(struct motion *m)
{
	if (m->threaded)
		sched_kick(m->sched);
}

#endif
