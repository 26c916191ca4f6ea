/* SPDX-License-Identifier: MIT */
#include "gcode.h"

#include <math.h>
#include <string.h>

#include "gcode_lex.h"

#define PI 3.14159265358979323846
#define TWO_PI (2.0 * PI)

static const char axis_letter[MOTION_MAX_AXES] = { 'X', 'Y', 'Z', 'A', 'B', 'C' };

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
			return gc_fail(err, MOTION_E_TRAVEL, line, col,
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
			return gc_fail(err, MOTION_E_TRAVEL, line, col,
				    "arc leaves the travel limits on axis %c (reaches %.4f mm, limits [%.4f, %.4f])",
				    axis_letter[ax], v, st->tmin[ax], st->tmax[ax]);
	}
	return 0;
}

/* ---- one block: modal groups, then what the block does --------------- */

/* The G- and M-codes of one block, sorted into their modal groups (G-code
 * numbers times ten, -1 where the block has none). */
struct block_modes {
	int motion_g, nonmodal, plane, units, dist;
	uint16_t motion_col, nonmodal_col;
	bool end_prog; /* M2 / M30 */
};

static int sort_g_codes(const struct words *ws, uint32_t line,
			struct block_modes *md, struct motion_error *err)
{
	md->motion_g = md->nonmodal = md->plane = md->units = md->dist = -1;
	md->motion_col = md->nonmodal_col = 0;
	for (int i = 0; i < ws->ng; i++) {
		int c = ws->g[i].code10;
		uint16_t col = ws->g[i].col;
		int *slot;
		uint16_t *scol = NULL;
		switch (c) {
		case 0: case 10: case 20: case 30:
			slot = &md->motion_g; scol = &md->motion_col; break;
		case 40: case 920: case 921:
			slot = &md->nonmodal; scol = &md->nonmodal_col; break;
		case 170: case 180: case 190:
			slot = &md->plane; break;
		case 200: case 210:
			slot = &md->units; break;
		case 900: case 910:
			slot = &md->dist; break;
		default:
			if (c % 10)
				return gc_fail(err, MOTION_E_UNSUPPORTED, line, col,
					       "unsupported G-code G%d.%d", c / 10, c % 10);
			return gc_fail(err, MOTION_E_UNSUPPORTED, line, col,
				       "unsupported G-code G%d", c / 10);
		}
		if (*slot >= 0)
			return gc_fail(err, MOTION_E_MODAL, line, col,
				       "G%g and G%g are in the same modal group",
				       *slot / 10.0, c / 10.0);
		*slot = c;
		if (scol)
			*scol = col;
	}
	return 0;
}

static int sort_m_codes(const struct words *ws, uint32_t line,
			struct block_modes *md, struct motion_error *err)
{
	if (ws->nm > 1)
		return gc_fail(err, MOTION_E_MODAL, line, ws->m[1].col,
			       "only one M-code per block is supported");
	md->end_prog = false;
	if (ws->nm == 1) {
		if (ws->m[0].code != 2 && ws->m[0].code != 30)
			return gc_fail(err, MOTION_E_UNSUPPORTED, line, ws->m[0].col,
				       "unsupported M-code M%d", ws->m[0].code);
		md->end_prog = true;
	}
	return 0;
}

/* The modal settings a block changes: units, plane, distance mode, feed. */
static int set_modes(struct gc_state *ns, const struct block_modes *md,
		     const struct words *ws, uint32_t line,
		     struct motion_error *err)
{
	if (md->units >= 0)
		ns->unit = md->units == 200 ? 25.4 : 1.0;
	if (md->plane >= 0)
		ns->plane = md->plane / 10;
	if (md->dist >= 0)
		ns->absolute = md->dist == 900;
	if (HAVE(ws, 'F')) {
		if (W(ws, 'F').v < 0)
			return gc_fail(err, MOTION_E_NUMBER, line, W(ws, 'F').col,
				       "feed rate must not be negative");
		ns->feed = W(ws, 'F').v * ns->unit / 60.0;
	}
	return 0;
}

/* The configured axes the block names (bit k: axis k). */
static int axis_words(const struct gc_state *ns, const struct words *ws,
		      uint32_t line, uint32_t *axmask, struct motion_error *err)
{
	*axmask = 0;
	for (uint32_t k = 0; k < MOTION_MAX_AXES; k++) {
		char L = axis_letter[k];
		if (!HAVE(ws, L))
			continue;
		if (k >= ns->n_axes)
			return gc_fail(err, MOTION_E_UNSUPPORTED, line, W(ws, L).col,
				       "axis '%c' is not configured (%u axes)", L,
				       (unsigned)ns->n_axes);
		*axmask |= 1u << k;
	}
	return 0;
}

static bool has_ijk(const struct words *ws)
{
	return HAVE(ws, 'I') || HAVE(ws, 'J') || HAVE(ws, 'K');
}

/* G4 P: dwell, in seconds. */
static int dwell_block(const struct gc_state *ns, const struct block_modes *md,
		       const struct words *ws, uint32_t axmask, uint32_t line,
		       struct gc_block *out, struct motion_error *err)
{
	if (axmask)
		return gc_fail(err, MOTION_E_MODAL, line, md->nonmodal_col,
			       "G4 does not take axis words");
	if (md->motion_g >= 0 || has_ijk(ws) || HAVE(ws, 'R'))
		return gc_fail(err, MOTION_E_MODAL, line, md->nonmodal_col,
			       "G4 cannot be combined with motion words");
	if (!HAVE(ws, 'P'))
		return gc_fail(err, MOTION_E_MISSING, line, md->nonmodal_col,
			       "G4 needs a dwell time P (seconds)");
	if (W(ws, 'P').v < 0)
		return gc_fail(err, MOTION_E_NUMBER, line, W(ws, 'P').col,
			       "dwell time must not be negative");
	out->kind = GC_DWELL;
	out->dwell = W(ws, 'P').v;
	memcpy(out->start, ns->pos, sizeof(ns->pos));
	memcpy(out->end, ns->pos, sizeof(ns->pos));
	return 0;
}

/* G92 (set the program position of the named axes) and G92.1 (clear). */
static int offset_block(struct gc_state *ns, const struct block_modes *md,
			const struct words *ws, uint32_t axmask, uint32_t line,
			struct motion_error *err)
{
	if (md->motion_g >= 0)
		return gc_fail(err, MOTION_E_MODAL, line, md->motion_col,
			       "G%g cannot be combined with G92 (both use the axis words)",
			       md->motion_g / 10.0);
	if (has_ijk(ws) || HAVE(ws, 'R') || HAVE(ws, 'P'))
		return gc_fail(err, MOTION_E_MODAL, line, md->nonmodal_col,
			       "G92 takes axis words only");
	if (md->nonmodal == 920) {
		if (!axmask)
			return gc_fail(err, MOTION_E_MISSING, line, md->nonmodal_col,
				       "G92 needs at least one axis word");
		for (uint32_t k = 0; k < ns->n_axes; k++)
			if (axmask & (1u << k))
				ns->offset[k] = ns->pos[k] -
					W(ws, axis_letter[k]).v * ns->unit;
	} else {
		if (axmask)
			return gc_fail(err, MOTION_E_MODAL, line, md->nonmodal_col,
				       "G92.1 does not take axis words");
		memset(ns->offset, 0, sizeof(ns->offset));
	}
	return 0;
}

/* ---- arcs ------------------------------------------------------------- */

/* The plane's two axes (right-handed with its normal), their centre-offset
 * letters, and the offset letter the plane does not take. */
struct plane_axes {
	int a0, a1;
	char o0, o1, bad;
};

static struct plane_axes plane_axes(int plane)
{
	switch (plane) {
	case 18: return (struct plane_axes){ 2, 0, 'K', 'I', 'J' };
	case 19: return (struct plane_axes){ 1, 2, 'J', 'K', 'I' };
	default: return (struct plane_axes){ 0, 1, 'I', 'J', 'K' };
	}
}

/* Centre of a radius-form arc from (s0, s1) to (e0, e1): R > 0 the short
 * way round, R < 0 the long way. */
static int centre_from_radius(const struct gc_state *ns, const struct words *ws,
			      bool ccw, const double *s, const double *e,
			      double *c, uint32_t line, struct motion_error *err)
{
	double R = W(ws, 'R').v * ns->unit;
	double dx = e[0] - s[0], dy = e[1] - s[1];
	double d = hypot(dx, dy);
	if (d < 1e-9)
		return gc_fail(err, MOTION_E_ARC, line, W(ws, 'R').col,
			       "radius-form arc needs an end point different from the start point");
	if (fabs(R) < 1e-9)
		return gc_fail(err, MOTION_E_ARC, line, W(ws, 'R').col,
			       "arc radius is zero");
	double h2 = R * R - d * d / 4.0;
	if (h2 < 0) {
		if (d / 2.0 - fabs(R) > 1e-6)
			return gc_fail(err, MOTION_E_ARC, line, W(ws, 'R').col,
				       "radius %.4f mm is too small for an end point %.4f mm away",
				       fabs(R), d);
		h2 = 0;
	}
	double sgn = (ccw ? 1.0 : -1.0) * (R > 0 ? 1.0 : -1.0);
	double h = sqrt(h2);
	c[0] = (s[0] + e[0]) / 2.0 + sgn * h * (-dy) / d;
	c[1] = (s[1] + e[1]) / 2.0 + sgn * h * dx / d;
	return 0;
}

/* Unsigned sweep from th0 to th1 in the arc's direction; a full circle
 * when the end point is the start point; P - 1 more turns. */
static int arc_sweep(const struct words *ws, double th0, double th1, bool full,
		     bool ccw, uint32_t line, double *out,
		     struct motion_error *err)
{
	double sweep;

	if (full)
		sweep = TWO_PI;
	else if (ccw)
		sweep = norm_angle(th1 - th0);
	else
		sweep = norm_angle(th0 - th1);
	if (!full && sweep < 1e-12)
		sweep = TWO_PI;
	if (HAVE(ws, 'P')) {
		double P = W(ws, 'P').v;
		if (P < 1 || P != floor(P) || P > 1000)
			return gc_fail(err, MOTION_E_NUMBER, line, W(ws, 'P').col,
				       "arc turns P must be an integer from 1 to 1000");
		sweep += (P - 1) * TWO_PI;
	}
	*out = sweep;
	return 0;
}

/* G2 / G3 to target: the arc's plane, centre, radii and sweep into *out. */
static int arc_block(const struct gc_state *ns, const struct words *ws,
		     const double *target, uint32_t mcol, uint32_t line,
		     struct gc_block *out, struct motion_error *err)
{
	struct plane_axes pa = plane_axes(ns->plane);
	bool has_r = HAVE(ws, 'R'), ijk = has_ijk(ws);

	if ((uint32_t)pa.a0 >= ns->n_axes || (uint32_t)pa.a1 >= ns->n_axes)
		return gc_fail(err, MOTION_E_UNSUPPORTED, line, mcol,
			       "plane G%d needs axes %c and %c", ns->plane,
			       axis_letter[pa.a0], axis_letter[pa.a1]);
	if (HAVE(ws, pa.bad))
		return gc_fail(err, MOTION_E_ARC, line, W(ws, pa.bad).col,
			       "'%c' is not an offset of plane G%d", pa.bad, ns->plane);
	if (has_r && ijk) {
		char L = HAVE(ws, pa.o0) ? pa.o0 : pa.o1;
		return gc_fail(err, MOTION_E_MODAL, line, W(ws, L).col,
			       "R cannot be combined with I/J/K");
	}
	if (!has_r && !ijk)
		return gc_fail(err, MOTION_E_MISSING, line, mcol,
			       "G%d needs a centre (I/J/K) or a radius (R)",
			       ns->motion);
	const double s[2] = { ns->pos[pa.a0], ns->pos[pa.a1] };
	const double e[2] = { target[pa.a0], target[pa.a1] };
	double c[2] = { 0.0, 0.0 };
	bool ccw = ns->motion == 3;
	if (has_r) {
		if (centre_from_radius(ns, ws, ccw, s, e, c, line, err))
			return -1;
	} else {
		double i0 = HAVE(ws, pa.o0) ? W(ws, pa.o0).v * ns->unit : 0.0;
		double i1 = HAVE(ws, pa.o1) ? W(ws, pa.o1).v * ns->unit : 0.0;
		c[0] = s[0] + i0;
		c[1] = s[1] + i1;
	}
	double r0 = hypot(s[0] - c[0], s[1] - c[1]);
	double r1 = hypot(e[0] - c[0], e[1] - c[1]);
	uint32_t acol = has_r ? W(ws, 'R').col
			      : W(ws, HAVE(ws, pa.o0) ? pa.o0 : pa.o1).col;
	if (r0 < 1e-6)
		return gc_fail(err, MOTION_E_ARC, line, acol,
			       "arc radius is zero (centre at the start point)");
	if (fabs(r1 - r0) > 0.002 && fabs(r1 - r0) > 0.001 * r0)
		return gc_fail(err, MOTION_E_ARC, line, acol,
			       "end point is not on the arc (start radius %.4f mm, end radius %.4f mm)",
			       r0, r1);
	double th0 = atan2(s[1] - c[1], s[0] - c[0]);
	double th1 = atan2(e[1] - c[1], e[0] - c[0]);
	bool full = hypot(e[0] - s[0], e[1] - s[1]) < 1e-9;
	double sweep = 0.0;
	if (arc_sweep(ws, th0, th1, full, ccw, line, &sweep, err))
		return -1;
	out->kind = GC_ARC;
	out->feed = ns->feed;
	out->a0 = (uint8_t)pa.a0;
	out->a1 = (uint8_t)pa.a1;
	out->c0 = c[0];
	out->c1 = c[1];
	out->r0 = r0;
	out->r1 = r1;
	out->theta0 = th0;
	out->sweep = ccw ? sweep : -sweep;
	return check_arc(ns, out, line, mcol, err);
}

/* ---- motion ----------------------------------------------------------- */

/* The words that only an arc takes (P, I/J/K, R) are refused elsewhere;
 * returns whether the block moves (axis words, or a G2/G3 full circle
 * given by its centre only). */
static int motion_words(const struct gc_state *ns, const struct words *ws,
			uint32_t axmask, uint32_t line, bool *move,
			struct motion_error *err)
{
	bool arc = ns->motion == 2 || ns->motion == 3;
	bool ijk = has_ijk(ws), has_r = HAVE(ws, 'R');

	if (HAVE(ws, 'P') && !arc)
		return gc_fail(err, MOTION_E_MODAL, line, W(ws, 'P').col,
			       "P is used only with G4 or G2/G3");
	if ((ijk || has_r) && !arc) {
		char L = has_r ? 'R' : HAVE(ws, 'I') ? 'I' : HAVE(ws, 'J') ? 'J' : 'K';
		return gc_fail(err, MOTION_E_MODAL, line, W(ws, L).col,
			       "'%c' is used only with G2/G3", L);
	}
	*move = axmask != 0 || (arc && ijk);
	if (!*move && arc && has_r)
		return gc_fail(err, MOTION_E_ARC, line, W(ws, 'R').col,
			       "radius-form arc needs an end point different from the start point");
	return 0;
}

/* G0 / G1 / G2 / G3 (the block's or the modal one). */
static int motion_block(struct gc_state *ns, const struct block_modes *md,
			const struct words *ws, uint32_t axmask, uint32_t line,
			struct gc_block *out, struct motion_error *err)
{
	bool move = false;

	if (md->motion_g >= 0)
		ns->motion = md->motion_g / 10;
	if (motion_words(ns, ws, axmask, line, &move, err))
		return -1;
	if (!move)
		return 0;
	if (ns->motion < 0) {
		uint32_t col = ws->first_col ? ws->first_col : 1;
		return gc_fail(err, MOTION_E_MISSING, line, col,
			       "axis words without a motion mode (G0, G1, G2 or G3)");
	}
	uint32_t mcol = md->motion_col ? md->motion_col
				       : (ws->first_col ? ws->first_col : 1);

	double target[MOTION_MAX_AXES];
	for (uint32_t k = 0; k < MOTION_MAX_AXES; k++) {
		target[k] = ns->pos[k];
		if (!(axmask & (1u << k)))
			continue;
		double v = W(ws, axis_letter[k]).v * ns->unit;
		target[k] = ns->absolute ? v + ns->offset[k] : ns->pos[k] + v;
	}
	memcpy(out->start, ns->pos, sizeof(ns->pos));
	memcpy(out->end, target, sizeof(target));
	if (check_point(ns, target, line, ws, mcol, err))
		return -1;

	if (ns->motion == 0) {
		out->kind = GC_RAPID;
	} else if (ns->feed <= 0) {
		return gc_fail(err, MOTION_E_MISSING, line, mcol,
			       "no feed rate programmed (F) for G%d", ns->motion);
	} else if (ns->motion == 1) {
		out->kind = GC_LINE;
		out->feed = ns->feed;
	} else if (arc_block(ns, ws, target, mcol, line, out, err)) {
		return -1;
	}
	memcpy(ns->pos, target, sizeof(target));
	return 0;
}

int gc_line(struct gc_state *st, const char *text, size_t len, uint32_t line,
	    struct gc_block *out, struct motion_error *err)
{
	struct words ws;
	struct gc_state ns = *st; /* committed only if the block is valid */
	struct block_modes md;
	uint32_t axmask;
	bool blank;
	int rc;

	memset(out, 0, sizeof(*out));
	out->kind = GC_NONE;
	out->line = line;
	if (gc_lex(text, len, line, &ws, &blank, err))
		return -1;
	if (blank)
		return 0;
	if (sort_g_codes(&ws, line, &md, err) || sort_m_codes(&ws, line, &md, err) ||
	    set_modes(&ns, &md, &ws, line, err) ||
	    axis_words(&ns, &ws, line, &axmask, err))
		return -1;
	if (md.nonmodal == 40)
		rc = dwell_block(&ns, &md, &ws, axmask, line, out, err);
	else if (md.nonmodal == 920 || md.nonmodal == 921)
		rc = offset_block(&ns, &md, &ws, axmask, line, err);
	else
		rc = motion_block(&ns, &md, &ws, axmask, line, out, err);
	if (rc)
		return -1;
	ns.ended = ns.ended || md.end_prog;
	*st = ns;
	return 0;
}
