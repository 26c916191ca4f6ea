/* SPDX-License-Identifier: MIT */
#define _POSIX_C_SOURCE 200809L
#include "check.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

void check_failf(const char *file, int line, const char *fmt, ...)
{
	va_list ap;

	if (file)
		fprintf(stdout, "  %s:%d: ", file, line);
	va_start(ap, fmt);
	vfprintf(stdout, fmt, ap);
	va_end(ap);
	if (!file)
		fputc('\n', stdout);
	fflush(stdout);
}

int test_main(int argc, char **argv, const struct test_case *cases, size_t n)
{
	int failed = 0, ran = 0;

	if (argc > 1 && strcmp(argv[1], "--list") == 0) {
		for (size_t i = 0; i < n; i++)
			printf("%s\n", cases[i].name);
		return 0;
	}
	for (size_t i = 0; i < n; i++) {
		bool want = argc <= 1;
		for (int a = 1; a < argc; a++)
			if (strcmp(argv[a], cases[i].name) == 0)
				want = true;
		if (!want)
			continue;
		ran++;
		int r = cases[i].fn();
		printf("%s %s\n", r ? "FAIL" : "ok", cases[i].name);
		fflush(stdout);
		failed += r != 0;
	}
	if (ran == 0) {
		printf("no test case matched\n");
		return 2;
	}
	printf("%d/%d passed\n", ran - failed, ran);
	return failed ? 1 : 0;
}

void trace_free(struct trace *tr)
{
	free(tr->sp);
	memset(tr, 0, sizeof(*tr));
}

static int trace_push(struct trace *tr, const struct motion_setpoint *sp)
{
	if (tr->n == tr->cap) {
		size_t cap = tr->cap ? tr->cap * 2 : 4096;
		struct motion_setpoint *p = realloc(tr->sp, cap * sizeof(*p));
		if (!p)
			return -1;
		tr->sp = p;
		tr->cap = cap;
	}
	tr->sp[tr->n++] = *sp;
	return 0;
}

int run_program(const struct motion_config *cfg, const char *text,
		size_t chunk, uint64_t max_cycles, struct trace *tr)
{
	struct motion *m;
	struct motion_setpoint sp;
	size_t len = strlen(text), off = 0;

	memset(tr, 0, sizeof(*tr));
	if (motion_create(cfg, &m, &tr->err)) {
		tr->has_err = true;
		return -1;
	}
	if (chunk == 0) {
		motion_load_program(m, text, len);
		off = len;
	}
	/* the first setpoint is the start position (holding) */
	for (uint64_t c = 0; c < max_cycles; c++) {
		while (off < len && motion_stream_flow(m) == MOTION_FLOW_XON) {
			size_t want = len - off < chunk ? len - off : chunk;
			long w = motion_stream_write(m, text + off, want);
			if (w <= 0)
				break;
			off += (size_t)w;
			if (off == len)
				motion_stream_end(m);
		}
		if (off == len && chunk)
			motion_stream_end(m);
		enum motion_status st = motion_next_setpoint(m, &sp);
		if (trace_push(tr, &sp)) {
			motion_destroy(m);
			return -1;
		}
		tr->final = st;
		if (st == MOTION_ST_DONE || st == MOTION_ST_FAULT ||
		    st == MOTION_ST_UNDERRUN)
			break;
	}
	const struct motion_error *e = motion_last_error(m);
	if (e) {
		tr->err = *e;
		tr->has_err = true;
	}
	motion_get_stats(m, &tr->stats);
	motion_destroy(m);
	return 0;
}

double sp_mm(const struct trace *tr, size_t i, unsigned k, double ipm)
{
	return tr->sp[i].pos[k] / ipm;
}

void measure(const struct trace *tr, double T, double ipm, struct measured *o)
{
	memset(o, 0, sizeof(*o));
	for (unsigned k = 0; k < MOTION_MAX_AXES; k++) {
		for (size_t i = 1; i < tr->n; i++) {
			double p0 = tr->sp[i - 1].pos[k], p1 = tr->sp[i].pos[k];
			double v = fabs(p1 - p0) / ipm / T;
			if (v > o->v[k]) {
				o->v[k] = v;
				o->v_at[k] = i;
			}
			double ff = tr->sp[i].vel[k] / ipm;
			double e = fabs(ff - (p1 - p0) / ipm / T);
			if (e > o->ff_err[k])
				o->ff_err[k] = e;
			if (fabs(ff) > o->ff_max[k])
				o->ff_max[k] = fabs(ff);
			if (i < 2)
				continue;
			double pm = tr->sp[i - 2].pos[k];
			double a = fabs(p1 - 2 * p0 + pm) / ipm / (T * T);
			if (a > o->a[k]) {
				o->a[k] = a;
				o->a_at[k] = i;
			}
			if (i < 3)
				continue;
			double pmm = tr->sp[i - 3].pos[k];
			double j = fabs(p1 - 3 * p0 + 3 * pm - pmm) / ipm / (T * T * T);
			if (j > o->j[k]) {
				o->j[k] = j;
				o->j_at[k] = i;
			}
		}
	}
}

int check_limits(const struct trace *tr, const struct motion_config *cfg,
		 char *why, size_t whylen)
{
	struct measured m;
	double T = cfg->period_us * 1e-6, ipm = cfg->increments_per_mm;
	double q = 1.0 / ipm; /* one increment, mm */
	static const char L[] = "XYZABC";

	measure(tr, T, ipm, &m);
	for (unsigned k = 0; k < cfg->n_axes; k++) {
		const struct motion_axis_limits *a = &cfg->axis[k];
		double vlim = a->vmax * (1 + 1e-9) + q / T;
		double alim = a->amax * (1 + 1e-9) + 2 * q / (T * T);
		double jlim = a->jmax * (1 + 1e-9) + 4 * q / (T * T * T);
		if (m.v[k] > vlim) {
			snprintf(why, whylen, "axis %c velocity %.6f > %.6f mm/s at cycle %zu",
				 L[k], m.v[k], a->vmax, m.v_at[k]);
			return -1;
		}
		if (m.a[k] > alim) {
			snprintf(why, whylen, "axis %c acceleration %.4f > %.4f mm/s^2 at cycle %zu",
				 L[k], m.a[k], a->amax, m.a_at[k]);
			return -1;
		}
		if (cfg->jerk_limited && m.j[k] > jlim) {
			snprintf(why, whylen, "axis %c jerk %.1f > %.1f mm/s^3 at cycle %zu",
				 L[k], m.j[k], a->jmax, m.j_at[k]);
			return -1;
		}
		if (m.ff_max[k] > a->vmax * (1 + 1e-9) + q) {
			snprintf(why, whylen, "axis %c feed-forward %.6f > %.6f mm/s",
				 L[k], m.ff_max[k], a->vmax);
			return -1;
		}
		double fftol = a->amax * T + q / T + q;
		if (m.ff_err[k] > fftol) {
			snprintf(why, whylen, "axis %c feed-forward differs from the motion by %.6f mm/s (> %.6f)",
				 L[k], m.ff_err[k], fftol);
			return -1;
		}
		for (size_t i = 0; i < tr->n; i++) {
			double x = tr->sp[i].pos[k] / ipm;
			if (x < a->min - q || x > a->max + q) {
				snprintf(why, whylen, "axis %c at %.6f outside travel at cycle %zu",
					 L[k], x, i);
				return -1;
			}
		}
	}
	return 0;
}
