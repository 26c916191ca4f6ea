/* SPDX-License-Identifier: MIT */
#include "gcode.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#define PI 3.14159265358979323846
#define TWO_PI (2.0 * PI)

static const char axis_letter[MOTION_MAX_AXES] = { 'X', 'Y', 'Z', 'A', 'B', 'C' };

static int fail(struct motion_error *err, enum motion_errcode code,
		uint32_t line, uint32_t col, const char *fmt, ...)
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

void gc_init(struct gc_state *st, const struct motion_config *cfg)
{
	memset(st, 0, sizeof(*st));
	st->n_axes = cfg->n_axes;
	st->unit = 1.0;
	st->absolute = true;
	st->plane = 17;
	st->motion = -1;
	for (uint32_t k = 0; k < MOTION_MAX_AXES; k++) {
		st->pos[k] = k < cfg->n_axes ? cfg->start_pos[k] : 0.0;
		st->tmin[k] = cfg->axis[k].min;
		st->tmax[k] = cfg->axis[k].max;
	}
}

/* ---- lexical level ---------------------------------------------------- */

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
			while (zeros-- > 0)
				mant *= 10;
			zeros = 0;
		} else if (mant || d) {
			sig++;
		}
		if (sig > 15 || frac > 22) {
			*why = "number has too many digits (at most 15 significant)";
			return -1;
		}
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

static int lex(const char *s, size_t len, uint32_t line, struct words *ws,
	       bool *blank, struct motion_error *err)
{
	size_t i = 0;

	memset(ws, 0, sizeof(*ws));
	*blank = true;
	/* a lone '%' (program delimiter) is ignored */
	{
		size_t a = 0, b = len;
		while (a < b && (s[a] == ' ' || s[a] == '\t' || s[a] == '\r'))
			a++;
		while (b > a && (s[b - 1] == ' ' || s[b - 1] == '\t' ||
				 s[b - 1] == '\r'))
			b--;
		if (b - a == 1 && s[a] == '%')
			return 0;
	}
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
			size_t j = i + 1;
			while (j < len && s[j] != ')') {
				if (s[j] == '(')
					return fail(err, MOTION_E_SYNTAX, line,
						    (uint32_t)j + 1u,
						    "nested comment");
				j++;
			}
			if (j >= len)
				return fail(err, MOTION_E_SYNTAX, line, col,
					    "unclosed comment");
			i = j + 1;
			continue;
		}
		if (c == ')')
			return fail(err, MOTION_E_SYNTAX, line, col,
				    "')' without '('");
		if ((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z')) {
			char L = (char)(c & ~0x20);
			const char *why = NULL;
			double v;
			i++;
			while (i < len && (s[i] == ' ' || s[i] == '\t'))
				i++;
			if (parse_number(s, len, &i, &v, &why))
				return fail(err, MOTION_E_NUMBER, line, col,
					    "%s after '%c'", why, L);
			if (*blank)
				ws->first_col = (uint16_t)col;
			switch (L) {
			case 'N':
				if (!*blank)
					return fail(err, MOTION_E_SYNTAX, line, col,
						    "line number N must come first");
				if (v < 0 || v != floor(v))
					return fail(err, MOTION_E_NUMBER, line, col,
						    "line number must be a non-negative integer");
				*blank = false;
				ws->first_col = 0;
				continue;
			case 'G': {
				double t = v * 10.0;
				long code10 = lround(t);
				if (v < 0 || fabs(t - (double)code10) > 1e-6)
					return fail(err, MOTION_E_NUMBER, line, col,
						    "invalid G-code number G%g", v);
				if (ws->ng >= 8)
					return fail(err, MOTION_E_MODAL, line, col,
						    "too many G-codes in one block");
				ws->g[ws->ng].code10 = (int)code10;
				ws->g[ws->ng].col = (uint16_t)col;
				ws->ng++;
				break;
			}
			case 'M':
				if (v < 0 || v != floor(v))
					return fail(err, MOTION_E_NUMBER, line, col,
						    "invalid M-code number M%g", v);
				if (ws->nm >= 4)
					return fail(err, MOTION_E_MODAL, line, col,
						    "too many M-codes in one block");
				ws->m[ws->nm].code = (int)v;
				ws->m[ws->nm].col = (uint16_t)col;
				ws->nm++;
				break;
			case 'F': case 'X': case 'Y': case 'Z': case 'A':
			case 'B': case 'C': case 'I': case 'J': case 'K':
			case 'R': case 'P':
				if (HAVE(ws, L))
					return fail(err, MOTION_E_MODAL, line, col,
						    "word '%c' appears twice", L);
				ws->have |= 1u << (L - 'A');
				W(ws, L).v = v;
				W(ws, L).col = (uint16_t)col;
				break;
			default:
				return fail(err, MOTION_E_UNSUPPORTED, line, col,
					    "unsupported word '%c'", L);
			}
			*blank = false;
			continue;
		}
		if ((unsigned char)c >= 0x20 && (unsigned char)c < 0x7f)
			return fail(err, MOTION_E_SYNTAX, line, col,
				    "unexpected character '%c'", c);
		return fail(err, MOTION_E_SYNTAX, line, col,
			    "unexpected character 0x%02x", (unsigned char)c);
	}
	return 0;
}

/* ---- semantic level --------------------------------------------------- */

static double norm_angle(double a) /* into [0, 2pi) */
{
	a = fmod(a, TWO_PI);
	if (a < 0)
		a += TWO_PI;
	return a;
}

static bool angle_in_sweep(double theta0, double sweep, double a)
{
	if (fabs(sweep) >= TWO_PI)
		return true;
	double d = sweep > 0 ? norm_angle(a - theta0) : norm_angle(theta0 - a);
	return d <= fabs(sweep);
}

static int check_point(const struct gc_state *st, const double *p, uint32_t line,
		       const struct words *ws, uint32_t defcol,
		       struct motion_error *err)
{
	for (uint32_t k = 0; k < st->n_axes; k++) {
		if (p[k] < st->tmin[k] - 1e-9 || p[k] > st->tmax[k] + 1e-9) {
			char L = axis_letter[k];
			uint32_t col = HAVE(ws, L) ? W(ws, L).col : defcol;
			return fail(err, MOTION_E_TRAVEL, line, col,
				    "%c target %.4f mm is outside the travel limits [%.4f, %.4f]",
				    L, p[k], st->tmin[k], st->tmax[k]);
		}
	}
	return 0;
}

static int check_arc(const struct gc_state *st, const struct gc_block *b,
		     uint32_t line, uint32_t col, struct motion_error *err)
{
	double rmax = b->r0 > b->r1 ? b->r0 : b->r1;
	static const double card[4] = { 0.0, PI / 2, PI, 3 * PI / 2 };

	for (int q = 0; q < 4; q++) {
		if (!angle_in_sweep(b->theta0, b->sweep, card[q]))
			continue;
		double x = b->c0 + rmax * cos(card[q]);
		double y = b->c1 + rmax * sin(card[q]);
		uint8_t ax = (q == 0 || q == 2) ? b->a0 : b->a1;
		double v = (q == 0 || q == 2) ? x : y;
		if (v < st->tmin[ax] - 1e-9 || v > st->tmax[ax] + 1e-9)
			return fail(err, MOTION_E_TRAVEL, line, col,
				    "arc leaves the travel limits on axis %c (reaches %.4f mm, limits [%.4f, %.4f])",
				    axis_letter[ax], v, st->tmin[ax], st->tmax[ax]);
	}
	return 0;
}

int gc_line(struct gc_state *st, const char *text, size_t len, uint32_t line,
	    struct gc_block *out, struct motion_error *err)
{
	struct words ws;
	struct gc_state ns = *st;
	bool blank;
	int motion_g = -1, nonmodal = -1, plane = -1, units = -1, dist = -1;
	uint16_t motion_col = 0, nonmodal_col = 0;

	memset(out, 0, sizeof(*out));
	out->kind = GC_NONE;
	out->line = line;
	if (lex(text, len, line, &ws, &blank, err))
		return -1;
	if (blank)
		return 0;

	/* modal groups */
	for (int i = 0; i < ws.ng; i++) {
		int c = ws.g[i].code10;
		uint16_t col = ws.g[i].col;
		int *slot;
		uint16_t *scol = NULL;
		switch (c) {
		case 0: case 10: case 20: case 30:
			slot = &motion_g; scol = &motion_col; break;
		case 40: case 920: case 921:
			slot = &nonmodal; scol = &nonmodal_col; break;
		case 170: case 180: case 190:
			slot = &plane; break;
		case 200: case 210:
			slot = &units; break;
		case 900: case 910:
			slot = &dist; break;
		default:
			if (c % 10)
				return fail(err, MOTION_E_UNSUPPORTED, line, col,
					    "unsupported G-code G%d.%d", c / 10, c % 10);
			return fail(err, MOTION_E_UNSUPPORTED, line, col,
				    "unsupported G-code G%d", c / 10);
		}
		if (*slot >= 0)
			return fail(err, MOTION_E_MODAL, line, col,
				    "G%g and G%g are in the same modal group",
				    *slot / 10.0, c / 10.0);
		*slot = c;
		if (scol)
			*scol = col;
	}
	if (ws.nm > 1)
		return fail(err, MOTION_E_MODAL, line, ws.m[1].col,
			    "only one M-code per block is supported");
	bool end_prog = false;
	if (ws.nm == 1) {
		if (ws.m[0].code != 2 && ws.m[0].code != 30)
			return fail(err, MOTION_E_UNSUPPORTED, line, ws.m[0].col,
				    "unsupported M-code M%d", ws.m[0].code);
		end_prog = true;
	}
	if (units >= 0)
		ns.unit = units == 200 ? 25.4 : 1.0;
	if (plane >= 0)
		ns.plane = plane / 10;
	if (dist >= 0)
		ns.absolute = dist == 900;
	if (HAVE(&ws, 'F')) {
		if (W(&ws, 'F').v < 0)
			return fail(err, MOTION_E_NUMBER, line, W(&ws, 'F').col,
				    "feed rate must not be negative");
		ns.feed = W(&ws, 'F').v * ns.unit / 60.0;
	}

	/* axis words */
	uint32_t axmask = 0;
	for (uint32_t k = 0; k < MOTION_MAX_AXES; k++) {
		char L = axis_letter[k];
		if (!HAVE(&ws, L))
			continue;
		if (k >= ns.n_axes)
			return fail(err, MOTION_E_UNSUPPORTED, line, W(&ws, L).col,
				    "axis '%c' is not configured (%u axes)", L,
				    (unsigned)ns.n_axes);
		axmask |= 1u << k;
	}
	bool has_ijk = HAVE(&ws, 'I') || HAVE(&ws, 'J') || HAVE(&ws, 'K');
	bool has_r = HAVE(&ws, 'R');
	bool has_p = HAVE(&ws, 'P');

	if (nonmodal == 40) { /* G4 dwell */
		if (axmask)
			return fail(err, MOTION_E_MODAL, line, nonmodal_col,
				    "G4 does not take axis words");
		if (motion_g >= 0 || has_ijk || has_r)
			return fail(err, MOTION_E_MODAL, line, nonmodal_col,
				    "G4 cannot be combined with motion words");
		if (!has_p)
			return fail(err, MOTION_E_MISSING, line, nonmodal_col,
				    "G4 needs a dwell time P (seconds)");
		if (W(&ws, 'P').v < 0)
			return fail(err, MOTION_E_NUMBER, line, W(&ws, 'P').col,
				    "dwell time must not be negative");
		out->kind = GC_DWELL;
		out->dwell = W(&ws, 'P').v;
		memcpy(out->start, ns.pos, sizeof(ns.pos));
		memcpy(out->end, ns.pos, sizeof(ns.pos));
		ns.ended = ns.ended || end_prog;
		*st = ns;
		return 0;
	}
	if (nonmodal == 920 || nonmodal == 921) {
		if (motion_g >= 0)
			return fail(err, MOTION_E_MODAL, line, motion_col,
				    "G%g cannot be combined with G92 (both use the axis words)",
				    motion_g / 10.0);
		if (has_ijk || has_r || has_p)
			return fail(err, MOTION_E_MODAL, line, nonmodal_col,
				    "G92 takes axis words only");
		if (nonmodal == 920) {
			if (!axmask)
				return fail(err, MOTION_E_MISSING, line, nonmodal_col,
					    "G92 needs at least one axis word");
			for (uint32_t k = 0; k < ns.n_axes; k++)
				if (axmask & (1u << k))
					ns.offset[k] = ns.pos[k] -
						W(&ws, axis_letter[k]).v * ns.unit;
		} else {
			if (axmask)
				return fail(err, MOTION_E_MODAL, line, nonmodal_col,
					    "G92.1 does not take axis words");
			memset(ns.offset, 0, sizeof(ns.offset));
		}
		ns.ended = ns.ended || end_prog;
		*st = ns;
		return 0;
	}

	if (motion_g >= 0)
		ns.motion = motion_g / 10;
	bool arc = ns.motion == 2 || ns.motion == 3;
	if (has_p && !arc)
		return fail(err, MOTION_E_MODAL, line, W(&ws, 'P').col,
			    "P is used only with G4 or G2/G3");
	if ((has_ijk || has_r) && !arc) {
		char L = has_r ? 'R' : HAVE(&ws, 'I') ? 'I' : HAVE(&ws, 'J') ? 'J' : 'K';
		return fail(err, MOTION_E_MODAL, line, W(&ws, L).col,
			    "'%c' is used only with G2/G3", L);
	}
	/* motion happens with axis words, or for a G2/G3 full circle given
	 * by its centre only */
	bool move = axmask != 0 || (arc && has_ijk);
	if (!move) {
		if (arc && has_r)
			return fail(err, MOTION_E_ARC, line, W(&ws, 'R').col,
				    "radius-form arc needs an end point different from the start point");
		ns.ended = ns.ended || end_prog;
		*st = ns;
		return 0;
	}
	if (ns.motion < 0) {
		uint32_t col = ws.first_col ? ws.first_col : 1;
		return fail(err, MOTION_E_MISSING, line, col,
			    "axis words without a motion mode (G0, G1, G2 or G3)");
	}
	uint32_t mcol = motion_col ? motion_col : (ws.first_col ? ws.first_col : 1);

	double target[MOTION_MAX_AXES];
	for (uint32_t k = 0; k < MOTION_MAX_AXES; k++) {
		target[k] = ns.pos[k];
		if (!(axmask & (1u << k)))
			continue;
		double v = W(&ws, axis_letter[k]).v * ns.unit;
		target[k] = ns.absolute ? v + ns.offset[k] : ns.pos[k] + v;
	}
	memcpy(out->start, ns.pos, sizeof(ns.pos));
	memcpy(out->end, target, sizeof(target));
	if (check_point(&ns, target, line, &ws, mcol, err))
		return -1;

	if (ns.motion == 0) {
		out->kind = GC_RAPID;
	} else if (ns.feed <= 0) {
		return fail(err, MOTION_E_MISSING, line, mcol,
			    "no feed rate programmed (F) for G%d", ns.motion);
	} else if (ns.motion == 1) {
		out->kind = GC_LINE;
		out->feed = ns.feed;
	} else {
		int a0, a1;
		char o0, o1, bad;
		switch (ns.plane) {
		case 18: a0 = 2; a1 = 0; o0 = 'K'; o1 = 'I'; bad = 'J'; break;
		case 19: a0 = 1; a1 = 2; o0 = 'J'; o1 = 'K'; bad = 'I'; break;
		default: a0 = 0; a1 = 1; o0 = 'I'; o1 = 'J'; bad = 'K'; break;
		}
		if ((uint32_t)a0 >= ns.n_axes || (uint32_t)a1 >= ns.n_axes)
			return fail(err, MOTION_E_UNSUPPORTED, line, mcol,
				    "plane G%d needs axes %c and %c", ns.plane,
				    axis_letter[a0], axis_letter[a1]);
		if (HAVE(&ws, bad))
			return fail(err, MOTION_E_ARC, line, W(&ws, bad).col,
				    "'%c' is not an offset of plane G%d", bad, ns.plane);
		if (has_r && has_ijk) {
			char L = HAVE(&ws, o0) ? o0 : o1;
			return fail(err, MOTION_E_MODAL, line, W(&ws, L).col,
				    "R cannot be combined with I/J/K");
		}
		if (!has_r && !has_ijk)
			return fail(err, MOTION_E_MISSING, line, mcol,
				    "G%d needs a centre (I/J/K) or a radius (R)",
				    ns.motion);
		double s0 = ns.pos[a0], s1 = ns.pos[a1];
		double e0 = target[a0], e1 = target[a1];
		double c0, c1;
		bool ccw = ns.motion == 3;
		if (has_r) {
			double R = W(&ws, 'R').v * ns.unit;
			double dx = e0 - s0, dy = e1 - s1;
			double d = hypot(dx, dy);
			if (d < 1e-9)
				return fail(err, MOTION_E_ARC, line, W(&ws, 'R').col,
					    "radius-form arc needs an end point different from the start point");
			if (fabs(R) < 1e-9)
				return fail(err, MOTION_E_ARC, line, W(&ws, 'R').col,
					    "arc radius is zero");
			double h2 = R * R - d * d / 4.0;
			if (h2 < 0) {
				if (d / 2.0 - fabs(R) > 1e-6)
					return fail(err, MOTION_E_ARC, line, W(&ws, 'R').col,
						    "radius %.4f mm is too small for an end point %.4f mm away",
						    fabs(R), d);
				h2 = 0;
			}
			double sgn = (ccw ? 1.0 : -1.0) * (R > 0 ? 1.0 : -1.0);
			double h = sqrt(h2);
			c0 = (s0 + e0) / 2.0 + sgn * h * (-dy) / d;
			c1 = (s1 + e1) / 2.0 + sgn * h * dx / d;
		} else {
			double i0 = HAVE(&ws, o0) ? W(&ws, o0).v * ns.unit : 0.0;
			double i1 = HAVE(&ws, o1) ? W(&ws, o1).v * ns.unit : 0.0;
			c0 = s0 + i0;
			c1 = s1 + i1;
		}
		double r0 = hypot(s0 - c0, s1 - c1);
		double r1 = hypot(e0 - c0, e1 - c1);
		uint32_t acol = has_r ? W(&ws, 'R').col : W(&ws, HAVE(&ws, o0) ? o0 : o1).col;
		if (r0 < 1e-6)
			return fail(err, MOTION_E_ARC, line, acol,
				    "arc radius is zero (centre at the start point)");
		if (fabs(r1 - r0) > 0.002 && fabs(r1 - r0) > 0.001 * r0)
			return fail(err, MOTION_E_ARC, line, acol,
				    "end point is not on the arc (start radius %.4f mm, end radius %.4f mm)",
				    r0, r1);
		double th0 = atan2(s1 - c1, s0 - c0);
		double th1 = atan2(e1 - c1, e0 - c0);
		double sweep;
		bool full = hypot(e0 - s0, e1 - s1) < 1e-9;
		if (full)
			sweep = TWO_PI;
		else if (ccw)
			sweep = norm_angle(th1 - th0);
		else
			sweep = norm_angle(th0 - th1);
		if (!full && sweep < 1e-12)
			sweep = TWO_PI;
		if (has_p) {
			double P = W(&ws, 'P').v;
			if (P < 1 || P != floor(P) || P > 1000)
				return fail(err, MOTION_E_NUMBER, line, W(&ws, 'P').col,
					    "arc turns P must be an integer from 1 to 1000");
			sweep += (P - 1) * TWO_PI;
		}
		out->kind = GC_ARC;
		out->feed = ns.feed;
		out->a0 = (uint8_t)a0;
		out->a1 = (uint8_t)a1;
		out->c0 = c0;
		out->c1 = c1;
		out->r0 = r0;
		out->r1 = r1;
		out->theta0 = th0;
		out->sweep = ccw ? sweep : -sweep;
		if (check_arc(&ns, out, line, mcol, err))
			return -1;
	}
	memcpy(ns.pos, target, sizeof(target));
	ns.ended = ns.ended || end_prog;
	*st = ns;
	return 0;
}
