// SPDX-License-Identifier: MIT
/*
 * fuzz_gcode - the G-code decoder (motion/src/gcode.c, gcode_lex.c) on
 * arbitrary text, then the same text through the motion pipeline's decode
 * stage and the stages after it for a bounded number of cycles.
 *
 * Line level, for 3 and 6 configured axes: gc_line() returns 0 or -1; an
 * error has a code, the line it was given, a column inside the line (or
 * just past it) and a message, and leaves the modal state as it was; a
 * block has a known kind, finite numbers, an end point inside the travel
 * limits, a feed >= 0, a dwell >= 0 and an arc with a positive radius.
 *
 * Pipeline level: motion_load_program() and at most PIPE_CYCLES calls of
 * motion_next_setpoint() (synchronous): every setpoint is inside the
 * travel limits, with a known status, and a fault carries an error. No
 * UB (UBSan), no read past the text (the text is a heap copy of exactly
 * its length), no hang (libFuzzer's -timeout).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gcode.h"
#include "motion/motion.h"

#define PIPE_CYCLES 3000u

#include "fuzz_assert.h"

static void check_block(const struct gc_state *st, const struct gc_block *b,
			uint32_t line)
{
	FZ_ASSERT(b->line == line);
	FZ_ASSERT(b->kind == GC_NONE || b->kind == GC_RAPID || b->kind == GC_LINE ||
		  b->kind == GC_ARC || b->kind == GC_DWELL);
	if (b->kind == GC_NONE)
		return;
	for (uint32_t k = 0; k < MOTION_MAX_AXES; k++) {
		FZ_ASSERT(isfinite(b->start[k]) && isfinite(b->end[k]));
		if (k < st->n_axes)
			FZ_ASSERT(b->end[k] >= st->tmin[k] - 1e-6 &&
				  b->end[k] <= st->tmax[k] + 1e-6);
	}
	FZ_ASSERT(isfinite(b->feed) && b->feed >= 0);
	FZ_ASSERT(isfinite(b->dwell) && b->dwell >= 0);
	if (b->kind == GC_LINE || b->kind == GC_ARC)
		FZ_ASSERT(b->feed > 0);
	if (b->kind == GC_ARC) {
		FZ_ASSERT(b->a0 < st->n_axes && b->a1 < st->n_axes && b->a0 != b->a1);
		FZ_ASSERT(isfinite(b->c0) && isfinite(b->c1) && isfinite(b->theta0));
		FZ_ASSERT(isfinite(b->r0) && isfinite(b->r1) && b->r0 > 0 && b->r1 > 0);
		FZ_ASSERT(isfinite(b->sweep) && b->sweep != 0);
	}
}

static void lines(const char *text, size_t size, uint32_t n_axes)
{
	struct motion_config cfg;
	struct gc_state st, before;
	struct gc_block b;
	struct motion_error e;
	uint32_t line = 0;
	size_t at = 0;

	motion_config_default(&cfg);
	cfg.n_axes = n_axes;
	gc_init(&st, &cfg);
	while (at < size) {
		const char *nl = memchr(text + at, '\n', size - at);
		size_t len = nl ? (size_t)(nl - (text + at)) : size - at;
		/* a line of exactly len bytes on the heap: ASan sees one more */
		char *ln = malloc(len ? len : 1u);

		FZ_ASSERT(ln);
		memcpy(ln, text + at, len);
		line++;
		before = st;
		memset(&e, 0, sizeof(e));
		if (gc_line(&st, ln, len, line, &b, &e) == 0) {
			check_block(&st, &b, line);
		} else {
			FZ_ASSERT(e.code > MOTION_E_NONE && e.code <= MOTION_E_TRAVEL);
			FZ_ASSERT(e.line == line);
			FZ_ASSERT(e.column >= 1 && e.column <= len + 1u);
			FZ_ASSERT(e.msg[0] != '\0' && memchr(e.msg, '\0', sizeof(e.msg)));
			FZ_ASSERT(memcmp(&st, &before, sizeof(st)) == 0);
		}
		free(ln);
		at += len + (nl ? 1u : 0u);
	}
}

static void pipeline(const char *text, size_t size)
{
	struct motion_config cfg;
	struct motion_error e;
	struct motion_setpoint sp;
	struct motion *m = NULL;

	motion_config_default(&cfg);
	FZ_ASSERT(motion_create(&cfg, &m, &e) == 0);
	FZ_ASSERT(motion_load_program(m, text, size) == 0);
	for (uint32_t i = 0; i < PIPE_CYCLES; i++) {
		enum motion_status s = motion_next_setpoint(m, &sp);

		FZ_ASSERT(s == MOTION_ST_MOVING || s == MOTION_ST_IDLE ||
			  s == MOTION_ST_DONE || s == MOTION_ST_FAULT);
		FZ_ASSERT(sp.status == (uint8_t)s && sp.n_axes == cfg.n_axes);
		for (uint32_t k = 0; k < cfg.n_axes; k++)
			FZ_ASSERT(sp.pos[k] >= cfg.axis[k].min * cfg.increments_per_mm - 1.0 &&
				  sp.pos[k] <= cfg.axis[k].max * cfg.increments_per_mm + 1.0);
		if (s == MOTION_ST_FAULT) {
			const struct motion_error *le = motion_last_error(m);

			FZ_ASSERT(le && le->code != MOTION_E_NONE && le->msg[0]);
			break;
		}
		if (s == MOTION_ST_DONE)
			break;
	}
	motion_destroy(m);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	char *text = malloc(size ? size : 1u);

	if (!text)
		return 0;
	memcpy(text, data, size);
	lines(text, size, 3);
	lines(text, size, MOTION_MAX_AXES);
	pipeline(text, size);
	free(text);
	return 0;
}
