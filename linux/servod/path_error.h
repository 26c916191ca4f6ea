/* SPDX-License-Identifier: MIT */
/*
 * path_error.h - the path error of a program run (docs/cycle.md, section
 * 2b), measured on every new feedback record. The feedback names the
 * command sequence the servo consumed (fb.cmd_seq) and its actual position
 * is the plant's state when its fine interpolation reached that coarse
 * setpoint, so the commanded point to compare with is the one of that
 * sequence (a history of CMD_HISTORY commanded points): no guessed delay.
 *   following error (XY) = |commanded(cmd_seq) - actual|
 *   path (contour) error = distance from the actual point to the commanded
 *                          polyline (the last CONTOUR_SEGMENTS setpoints up
 *                          to the newest one), i.e. the deviation across
 *                          the path
 * Both in increments, reported in um too. Cycle thread, under the cycle
 * lock; read from a copy taken under it.
 */
#ifndef SERVOD_PATH_ERROR_H
#define SERVOD_PATH_ERROR_H

#include <stdint.h>

#include "amp/amp.h"

#define CMD_HISTORY 64u		/* commanded points kept by command sequence */
#define CONTOUR_SEGMENTS 24u	/* contour error: polyline segments looked at */
#define PE_AXES 3u		/* per-axis following error: X Y Z */

struct out;

struct path_point {
	uint32_t seq, line;
	int32_t x, y;
};

struct path_error {
	struct path_point hist[CMD_HISTORY];
	uint32_t newest;		/* command sequence of the newest point */
	/* the run being measured */
	uint32_t seq_first, seq_last;	/* command sequences of the program (last: 0 = open) */
	int measuring;
	uint64_t samples, align_mismatch, cmd_skips;
	uint32_t last_fb_seq;
	double pe_max, pe_sq, fe_max, fe_sq;	/* increments */
	uint32_t pe_max_line, fe_max_line;
	int32_t pe_max_at[2];
	int32_t axis_fe_max[PE_AXES];
};

/* The figures of a new run (nothing measured until path_error_start). */
void path_error_reset(struct path_error *pe);
/* The run's first command sequence: measuring from there. */
void path_error_start(struct path_error *pe, uint32_t seq);
/* The run ended: measured up to the last command it sent. */
void path_error_end(struct path_error *pe);
/* The commands of sequence seq (XY: axes 0 and 1), from source line line. */
void path_error_command(struct path_error *pe, uint32_t seq, uint32_t line, const struct amp_cmd_axis *cmd,
			uint32_t n);
/* A new feedback record. */
void path_error_feedback(struct path_error *pe, const struct amp_fb_record *fb, uint32_t n);
/* "motion.samples" .. "motion.cmd_skips" lines; um at inc_per_mm. */
void path_error_format(const struct path_error *pe, struct out *o, double inc_per_mm);

#endif
