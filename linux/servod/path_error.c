// SPDX-License-Identifier: MIT
/* path_error.c - the path error of a program run (path_error.h). */
#define _GNU_SOURCE
#include <math.h>
#include <string.h>

#include "control.h"
#include "path_error.h"

void path_error_reset(struct path_error *pe)
{
	pe->measuring = 0;
	pe->seq_first = pe->seq_last = 0;
	pe->samples = pe->align_mismatch = pe->cmd_skips = 0;
	pe->pe_max = pe->pe_sq = pe->fe_max = pe->fe_sq = 0.0;
	pe->pe_max_line = pe->fe_max_line = 0;
	memset(pe->pe_max_at, 0, sizeof(pe->pe_max_at));
	memset(pe->axis_fe_max, 0, sizeof(pe->axis_fe_max));
}

void path_error_start(struct path_error *pe, uint32_t seq)
{
	pe->seq_first = seq;
	pe->seq_last = 0;
	pe->measuring = 1;
}

void path_error_end(struct path_error *pe)
{
	pe->seq_last = pe->newest;
}

void path_error_command(struct path_error *pe, uint32_t seq, uint32_t line, const struct amp_cmd_axis *cmd,
			uint32_t n)
{
	struct path_point *h = &pe->hist[seq % CMD_HISTORY];

	h->seq = seq;
	h->line = line;
	h->x = n > 0 ? cmd[0].target_pos : 0;
	h->y = n > 1 ? cmd[1].target_pos : 0;
	pe->newest = seq;
}

static double seg_dist(double px, double py, const struct path_point *a, const struct path_point *b)
{
	double dx = (double)b->x - a->x, dy = (double)b->y - a->y;
	double l2 = dx * dx + dy * dy, t = 0.0;

	if (l2 > 0.0) {
		t = ((px - a->x) * dx + (py - a->y) * dy) / l2;
		t = t < 0.0 ? 0.0 : t > 1.0 ? 1.0 : t;
	}
	dx = a->x + t * dx - px;
	dy = a->y + t * dy - py;
	return sqrt(dx * dx + dy * dy);
}

/* Distance from (px, py) to the commanded polyline near sequence s, or fe. */
static double contour_error(const struct path_error *pe, uint32_t s, double px, double py, double fe)
{
	double best = INFINITY;

	for (uint32_t k = 1; k <= CONTOUR_SEGMENTS && k < CMD_HISTORY - 1u; k++) {
		uint32_t j = pe->newest - k;
		const struct path_point *a = &pe->hist[j % CMD_HISTORY], *b = &pe->hist[(j + 1u) % CMD_HISTORY];
		double d;

		if (a->seq != j || b->seq != j + 1u)
			break;
		d = seg_dist(px, py, a, b);
		if (d < best)
			best = d;
		if ((int32_t)(j - s) < -8)
			break;	/* far enough behind the aligned point */
	}
	return isfinite(best) ? best : fe;
}

void path_error_feedback(struct path_error *pe, const struct amp_fb_record *fb, uint32_t n)
{
	const struct path_point *h;
	double px, py, fe, e;
	uint32_t s;

	if (!pe->measuring || n < 2)
		return;
	s = fb->cmd_seq;
	if ((int32_t)(s - pe->seq_first) < 0)
		return;
	if (pe->seq_last && (int32_t)(s - pe->seq_last) > 0) {
		pe->measuring = 0;	/* past the program's last command */
		return;
	}
	if (pe->samples && s - pe->last_fb_seq > 1u)
		pe->cmd_skips += s - pe->last_fb_seq - 1u;
	pe->last_fb_seq = s;
	h = &pe->hist[s % CMD_HISTORY];
	if (h->seq != s || pe->newest - s >= CMD_HISTORY - 1u)
		return;	/* too old (should not happen: the servo is <= 2 cycles behind) */
	px = fb->axis[0].actual_pos;
	py = fb->axis[1].actual_pos;
	fe = hypot(px - h->x, py - h->y);
	/* the servo's own following error is p1 - actual: the same if aligned */
	if (fabs(hypot(fb->axis[0].following_error, fb->axis[1].following_error) - fe) > 1.5)
		pe->align_mismatch++;
	e = contour_error(pe, s, px, py, fe);
	pe->samples++;
	pe->fe_sq += fe * fe;
	pe->pe_sq += e * e;
	if (fe > pe->fe_max) {
		pe->fe_max = fe;
		pe->fe_max_line = h->line;
	}
	if (e > pe->pe_max) {
		pe->pe_max = e;
		pe->pe_max_line = h->line;
		pe->pe_max_at[0] = (int32_t)px;
		pe->pe_max_at[1] = (int32_t)py;
	}
	for (uint32_t i = 0; i < PE_AXES && i < n; i++) {
		int32_t a = fb->axis[i].following_error;

		a = a < 0 ? -a : a;
		if (a > pe->axis_fe_max[i])
			pe->axis_fe_max[i] = a;
	}
}

static double um(double inc, double inc_per_mm)
{
	return inc * 1000.0 / inc_per_mm;
}

void path_error_format(const struct path_error *pe, struct out *o, double inc_per_mm)
{
	double k = pe->samples ? 1.0 / (double)pe->samples : 0.0;

	put(o, "motion.samples=%llu\n", (unsigned long long)pe->samples);
	put(o, "motion.path_err.max_um=%.1f\nmotion.path_err.rms_um=%.2f\nmotion.path_err.max_line=%u\n",
	    um(pe->pe_max, inc_per_mm), um(sqrt(pe->pe_sq * k), inc_per_mm), pe->pe_max_line);
	put(o, "motion.path_err.max_at_inc=%d,%d\n", pe->pe_max_at[0], pe->pe_max_at[1]);
	put(o, "motion.follow_err.max_um=%.1f\nmotion.follow_err.rms_um=%.2f\nmotion.follow_err.max_line=%u\n",
	    um(pe->fe_max, inc_per_mm), um(sqrt(pe->fe_sq * k), inc_per_mm), pe->fe_max_line);
	put(o, "motion.follow_err.axis_max_inc=%d,%d,%d\n", pe->axis_fe_max[0], pe->axis_fe_max[1],
	    pe->axis_fe_max[2]);
	put(o, "motion.align_mismatch=%llu\nmotion.cmd_skips=%llu\n", (unsigned long long)pe->align_mismatch,
	    (unsigned long long)pe->cmd_skips);
}
