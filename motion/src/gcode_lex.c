/* SPDX-License-Identifier: MIT */
/* The G-code decoder's lexical level (see gcode_lex.h). */
#include "gcode_lex.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

int gc_fail(struct motion_error *err, enum motion_errcode code, uint32_t line,
	    uint32_t col, const char *fmt, ...)
{
	va_list ap;

	if (err) {
		err->code = code;
		err->line = line;
		err->column = col;
		va_start(ap, fmt);
		vsnprintf(err->msg, sizeof(err->msg), fmt, ap);
		va_end(ap);
	}
	return -1;
}

static const double pow10_tab[23] = {
	1e0,  1e1,  1e2,  1e3,  1e4,  1e5,  1e6,  1e7,  1e8,  1e9,  1e10, 1e11,
	1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
};

/* [+-]? (digits [. digits*] | . digits); locale independent; exact for up
 * to 15 significant digits.  Returns 0, or -1 with *why set. */
static int parse_number(const char *s, size_t len, size_t *pos, double *out,
			const char **why)
{
	size_t i = *pos;
	bool neg = false, dot = false;
	int64_t mant = 0;
	int sig = 0, frac = 0, zeros = 0, ndig = 0;

	if (i < len && (s[i] == '+' || s[i] == '-')) {
		neg = s[i] == '-';
		i++;
	}
	for (; i < len; i++) {
		char c = s[i];
		if (c == '.') {
			if (dot) {
				*why = "malformed number (two decimal points)";
				return -1;
			}
			dot = true;
			continue;
		}
		if (c < '0' || c > '9')
			break;
		ndig++;
		int d = c - '0';
		if (dot && d == 0) { /* trailing zeros count only if followed */
			zeros++;
			continue;
		}
		if (dot) {
			frac += zeros + 1;
			sig += (mant || d) ? zeros + 1 : 0;
		} else if (mant || d) {
			sig++;
		}
		/* before the zeros are multiplied in: 15 digits fit, more may
		 * not (1.5000...0004 overflowed int64 here) */
		if (sig > 15 || frac > 22) {
			*why = "number has too many digits (at most 15 significant)";
			return -1;
		}
		for (; zeros > 0; zeros--)
			mant *= 10;
		mant = mant * 10 + d;
	}
	if (ndig == 0) {
		*why = "missing or malformed number";
		return -1;
	}
	double v = (double)mant / pow10_tab[frac];
	if (v > 1e9) {
		*why = "number out of range";
		return -1;
	}
	*out = neg ? -v : v;
	*pos = i;
	return 0;
}

/* A line that holds only '%' (the program delimiter) and blanks. */
static bool lone_percent(const char *s, size_t len)
{
	size_t a = 0, b = len;

	while (a < b && (s[a] == ' ' || s[a] == '\t' || s[a] == '\r'))
		a++;
	while (b > a && (s[b - 1] == ' ' || s[b - 1] == '\t' || s[b - 1] == '\r'))
		b--;
	return b - a == 1 && s[a] == '%';
}

/* A ( ) comment starting at s[*i]; *i moves past its ')'. */
static int skip_comment(const char *s, size_t len, size_t *i, uint32_t line,
			struct motion_error *err)
{
	size_t j = *i + 1;

	while (j < len && s[j] != ')') {
		if (s[j] == '(')
			return gc_fail(err, MOTION_E_SYNTAX, line, (uint32_t)j + 1u,
				       "nested comment");
		j++;
	}
	if (j >= len)
		return gc_fail(err, MOTION_E_SYNTAX, line, (uint32_t)*i + 1u,
			       "unclosed comment");
	*i = j + 1;
	return 0;
}

/* Adds the word L v found at column col to *ws. */
static int add_word(struct words *ws, char L, double v, uint32_t col,
		    bool *blank, uint32_t line, struct motion_error *err)
{
	if (*blank)
		ws->first_col = (uint16_t)col;
	switch (L) {
	case 'N':
		if (!*blank)
			return gc_fail(err, MOTION_E_SYNTAX, line, col,
				       "line number N must come first");
		if (v < 0 || v != floor(v))
			return gc_fail(err, MOTION_E_NUMBER, line, col,
				       "line number must be a non-negative integer");
		ws->first_col = 0;
		break;
	case 'G': {
		double t = v * 10.0;
		long code10 = lround(t);
		if (v < 0 || fabs(t - (double)code10) > 1e-6)
			return gc_fail(err, MOTION_E_NUMBER, line, col,
				       "invalid G-code number G%g", v);
		if (ws->ng >= 8)
			return gc_fail(err, MOTION_E_MODAL, line, col,
				       "too many G-codes in one block");
		ws->g[ws->ng].code10 = (int)code10;
		ws->g[ws->ng].col = (uint16_t)col;
		ws->ng++;
		break;
	}
	case 'M':
		if (v < 0 || v != floor(v))
			return gc_fail(err, MOTION_E_NUMBER, line, col,
				       "invalid M-code number M%g", v);
		if (ws->nm >= 4)
			return gc_fail(err, MOTION_E_MODAL, line, col,
				       "too many M-codes in one block");
		ws->m[ws->nm].code = (int)v;
		ws->m[ws->nm].col = (uint16_t)col;
		ws->nm++;
		break;
	case 'F': case 'X': case 'Y': case 'Z': case 'A':
	case 'B': case 'C': case 'I': case 'J': case 'K':
	case 'R': case 'P':
		if (HAVE(ws, L))
			return gc_fail(err, MOTION_E_MODAL, line, col,
				       "word '%c' appears twice", L);
		ws->have |= 1u << (L - 'A');
		W(ws, L).v = v;
		W(ws, L).col = (uint16_t)col;
		break;
	default:
		return gc_fail(err, MOTION_E_UNSUPPORTED, line, col,
			       "unsupported word '%c'", L);
	}
	*blank = false;
	return 0;
}

int gc_lex(const char *s, size_t len, uint32_t line, struct words *ws,
	   bool *blank, struct motion_error *err)
{
	size_t i = 0;

	memset(ws, 0, sizeof(*ws));
	*blank = true;
	if (lone_percent(s, len)) /* a program delimiter: ignored */
		return 0;
	while (i < len) {
		char c = s[i];
		uint32_t col = (uint32_t)i + 1u;
		if (c == ' ' || c == '\t' || c == '\r') {
			i++;
			continue;
		}
		if (c == ';')
			break;
		if (c == '(') {
			if (skip_comment(s, len, &i, line, err))
				return -1;
			continue;
		}
		if (c == ')')
			return gc_fail(err, MOTION_E_SYNTAX, line, col,
				       "')' without '('");
		if ((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z')) {
			char L = (char)(c & ~0x20);
			const char *why = NULL;
			double v;
			i++;
			while (i < len && (s[i] == ' ' || s[i] == '\t'))
				i++;
			if (parse_number(s, len, &i, &v, &why))
				return gc_fail(err, MOTION_E_NUMBER, line, col,
					       "%s after '%c'", why, L);
			if (add_word(ws, L, v, col, blank, line, err))
				return -1;
			continue;
		}
		if ((unsigned char)c >= 0x20 && (unsigned char)c < 0x7f)
			return gc_fail(err, MOTION_E_SYNTAX, line, col,
				       "unexpected character '%c'", c);
		return gc_fail(err, MOTION_E_SYNTAX, line, col,
			       "unexpected character 0x%02x", (unsigned char)c);
	}
	return 0;
}
