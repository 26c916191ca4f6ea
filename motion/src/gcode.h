/* SPDX-License-Identifier: MIT */
/*
 * G-code decoder: one line in, at most one motion block out, with modal
 * state.  Supported: G0 G1 G2 G3 (I/J/K centre and R radius forms, P turns,
 * helices), G4 P, G17 G18 G19, G20 G21, G90 G91, G92 G92.1, F, M2 M30,
 * N line numbers, ( ) and ; comments, a lone %.  Everything else is an
 * error with line, column and reason.  All positions are machine
 * coordinates in millimetres.
 */
#ifndef SERVOAMP_MOTION_GCODE_H
#define SERVOAMP_MOTION_GCODE_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "motion/motion.h"

enum gc_kind { GC_NONE = 0, GC_RAPID, GC_LINE, GC_ARC, GC_DWELL, GC_END };

struct gc_block {
	enum gc_kind kind;
	uint32_t line;
	double start[MOTION_MAX_AXES];
	double end[MOTION_MAX_AXES];
	double feed;   /* mm/s (0 for rapid: axis limits only) */
	double dwell;  /* s */
	/* arcs: plane axes a0, a1 (right-handed with the plane normal) */
	uint8_t a0, a1;
	double c0, c1;     /* centre in the plane */
	double r0, r1;     /* start and end radius (equal within tolerance) */
	double theta0;     /* start angle, rad */
	double sweep;      /* signed: > 0 counter-clockwise (G3) */
};

struct gc_state {
	uint32_t n_axes;
	double unit;        /* mm per program unit: 1 or 25.4 */
	bool absolute;      /* G90 */
	int plane;          /* 17, 18, 19 */
	int motion;         /* 0, 1, 2, 3 (modal motion), -1 none yet */
	double feed;        /* mm/s, 0 = not set */
	double pos[MOTION_MAX_AXES];    /* machine position, mm */
	double offset[MOTION_MAX_AXES]; /* G92: machine = program + offset */
	double tmin[MOTION_MAX_AXES], tmax[MOTION_MAX_AXES];
	bool ended;         /* M2/M30 seen */
};

void gc_init(struct gc_state *st, const struct motion_config *cfg);

/* Decodes one line (without its newline).  Returns 0 and fills *out (kind
 * GC_NONE for lines without motion), or -1 and fills *err; on error the
 * state is left unchanged. */
int gc_line(struct gc_state *st, const char *text, size_t len, uint32_t line,
	    struct gc_block *out, struct motion_error *err);

#endif
