/* SPDX-License-Identifier: MIT */
/*
 * What a stage may ask of the pipeline that owns it: report a fault, say
 * that the run may have ended, and ask whether the look-ahead should stop
 * waiting for a full window.  The stages see struct motion only as this
 * opaque handle; pipeline_state.h defines it.
 */
#ifndef SERVOAMP_MOTION_PIPELINE_H
#define SERVOAMP_MOTION_PIPELINE_H

#include <stdbool.h>
#include <stdint.h>

#include "motion/motion.h"

/* The queues of the chain, in order (MOTION_N_QUEUES): the stream, then
 * one ring between each two stages; Q_PROFILES and Q_SETPOINTS are the
 * interpolation lanes' input and output rings, counted as one queue each
 * (interp.h). */
enum { Q_STREAM, Q_BLOCKS, Q_SEGS, Q_PLANNED, Q_PROFILES, Q_SETPOINTS };

/* The first fault wins; later ones are dropped.  Both wake motion_wait(). */
void pipeline_fail(struct motion *m, enum motion_errcode code, uint32_t line,
		   uint32_t col, const char *fmt, ...);
void pipeline_record(struct motion *m, const struct motion_error *e);
bool pipeline_faulted(const struct motion *m);

/* Wakes motion_wait() callers if the run has ended.  Called after each
 * change that can end it: the end marker passed (accel), the last piece
 * released by an interpolation lane, the last setpoint taken (a
 * consumer's release) or a fault. */
void pipeline_notify_end(struct motion *m);

/* The look-ahead emits without a full window when nothing more can arrive
 * for now (the input is dry) or, in threaded mode, when the setpoint
 * supply runs low. */
bool pipeline_starving(const struct motion *m);

/* At rest at the end of a segment, with the next one not planned yet:
 * stop there (a sample at rest, then idle) rather than wait for it. */
bool pipeline_rest_now(const struct motion *m);

#endif
