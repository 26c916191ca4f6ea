/* SPDX-License-Identifier: MIT */
/*
 * The decode stage: lines from the stream, one G-code block each into the
 * block ring (the language itself is gcode.h).  After M2/M30 or an error
 * it sends the end marker and discards the rest of the input.
 */
#ifndef SERVOAMP_MOTION_DECODE_H
#define SERVOAMP_MOTION_DECODE_H

#include <stdatomic.h>
#include <stdint.h>

#include "gcode.h"
#include "motion/motion.h"
#include "motion/ring.h"
#include "stream.h"

struct decode {
	/* wiring, read-only after decode_init() */
	struct motion *m;   /* for faults */
	struct stream *in;
	struct ring *out;   /* struct gc_block */
	uint32_t batch;
	/* state */
	struct gc_state gc;
	uint32_t lineno;
	atomic_bool end_pending, end_sent, stop;
	atomic_bool busy;
	_Atomic uint64_t n_lines, n_blocks, n_ignored;
	char linebuf[MOTION_MAX_LINE + 2];
};

void decode_init(struct decode *d, struct motion *m,
		 const struct motion_config *cfg, struct stream *in,
		 struct ring *out);

/* Scheduler task (arg: struct decode). */
void decode_levels(void *arg, uint32_t *ul, uint32_t *dl, uint32_t *dcap);
uint32_t decode_run(void *arg, unsigned worker);

#endif
