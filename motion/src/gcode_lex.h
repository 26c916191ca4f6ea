/* SPDX-License-Identifier: MIT */
/*
 * The G-code decoder's lexical level: a line into its words (letter and
 * number, with the column of each), N line numbers, ( ) and ; comments and
 * a lone % taken care of.  gcode.c gives the words their meaning.
 */
#ifndef SERVOAMP_MOTION_GCODE_LEX_H
#define SERVOAMP_MOTION_GCODE_LEX_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "motion/motion.h"

struct word {
	double v;
	uint16_t col;
};

struct words {
	uint32_t have; /* bit (letter - 'A') */
	struct word w[26];
	int ng;
	struct {
		int code10;
		uint16_t col;
	} g[8];
	int nm;
	struct {
		int code;
		uint16_t col;
	} m[4];
	uint16_t first_col;
};

#define HAVE(ws, c) (((ws)->have >> ((c) - 'A')) & 1u)
#define W(ws, c) ((ws)->w[(c) - 'A'])

/* Splits one line into *ws; *blank tells a line without words.  Returns 0,
 * or -1 with *err filled. */
int gc_lex(const char *s, size_t len, uint32_t line, struct words *ws,
	   bool *blank, struct motion_error *err);

/* Fills *err (if not NULL) and returns -1. */
int gc_fail(struct motion_error *err, enum motion_errcode code, uint32_t line,
	    uint32_t col, const char *fmt, ...);

#endif
