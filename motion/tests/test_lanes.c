/* SPDX-License-Identifier: MIT */
/*
 * Data-parallel interpolation (interp.h): the setpoints are the same bits
 * whatever the number of lanes, the chunk size and the number of workers,
 * with both profile kinds, and at the edges: an empty program, one
 * segment, segments shorter than a chunk, segments longer than several
 * chunks, one setpoint per chunk, dwells shorter than a period, stops, a
 * fault, an open stream that runs dry.  No timing is asserted.
 */
#define _POSIX_C_SOURCE 200809L
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"

/* Short arcs along a zigzag with a dwell, a reversal (a stop) and a
 * dwell shorter than one period now and then. */
static char *gen_program(int n)
{
	size_t cap = (size_t)n * 64 + 128, len = 0;
	char *p = malloc(cap);
	double x = 0, y = 0, dir = 1;

	if (!p)
		return NULL;
	len += (size_t)snprintf(p + len, cap - len, "G21 G90 F4000\n");
	for (int i = 1; i <= n; i++) {
		if (i % 40 == 0) {
			dir = -dir;
			y += 1.0;
			len += (size_t)snprintf(p + len, cap - len, "G1 Y%.3f\n", y);
			continue;
		}
		if (i % 53 == 0) {
			len += (size_t)snprintf(p + len, cap - len, "G4 P%s\n",
						i % 2 ? "0.0004" : "0.012");
			continue;
		}
		if (i % 61 == 0) { /* straight back: a stop at the junction */
			len += (size_t)snprintf(p + len, cap - len, "G1 X%.3f\nG1 X%.3f\n",
						x - 0.7 * dir, x);
			continue;
		}
		x += 0.5 * dir;
		len += (size_t)snprintf(p + len, cap - len, "G%d X%.3f R%.3f\n",
					i % 2 ? 2 : 3, x, i % 3 ? 0.4 : -0.3);
	}
	snprintf(p + len, cap - len, "M2\n");
	return p;
}

static int same_trace(const struct trace *a, const struct trace *b, char *why,
		      size_t n)
{
	if (a->n != b->n || a->final != b->final) {
		snprintf(why, n, "%zu setpoints (final %d) against %zu (final %d)",
			 b->n, (int)b->final, a->n, (int)a->final);
		return -1;
	}
	for (size_t i = 0; i < a->n; i++) {
		const struct motion_setpoint *x = &a->sp[i], *y = &b->sp[i];
		if (x->cycle != y->cycle || x->line != y->line ||
		    x->status != y->status || x->n_axes != y->n_axes ||
		    memcmp(x->pos, y->pos, sizeof(x->pos)) ||
		    memcmp(x->vel, y->vel, sizeof(x->vel))) {
			snprintf(why, n, "setpoint %zu differs (line %u/%u, x %d/%d, vx %d/%d)",
				 i, x->line, y->line, x->pos[0], y->pos[0],
				 x->vel[0], y->vel[0]);
			return -1;
		}
	}
	return 0;
}

static const uint32_t lanes_tried[] = { 1, 2, 3, 8 };
static const uint32_t chunks_tried[] = { 1, 2, 3, 7, 64, 1000 };

/* Every (lanes, chunk) against the serial interpolator: one lane, one
 * chunk for the whole run.  feed: stream chunk in bytes (0: loaded). */
static int same_all_ways(const struct motion_config *base, const char *prog,
			 size_t feed, size_t *n_out, enum motion_status *final)
{
	struct motion_config c = *base;
	struct trace ref, tr;
	char why[160];

	c.interp_lanes = 1;
	c.interp_chunk = 1u << 20;
	CHECK(run_program(&c, prog, feed, 5000000, &ref) == 0, "reference run failed");
	for (size_t li = 0; li < sizeof(lanes_tried) / sizeof(lanes_tried[0]); li++)
		for (size_t ci = 0; ci < sizeof(chunks_tried) / sizeof(chunks_tried[0]); ci++) {
			c.interp_lanes = lanes_tried[li];
			c.interp_chunk = chunks_tried[ci];
			CHECK(run_program(&c, prog, feed, 5000000, &tr) == 0, "run failed");
			int d = same_trace(&ref, &tr, why, sizeof(why));
			trace_free(&tr);
			CHECK(d == 0, "%s, %u lanes, chunk %u, feed %zu: %s",
			      base->jerk_limited ? "S-curve" : "trapezoid",
			      lanes_tried[li], chunks_tried[ci], feed, why);
		}
	*n_out = ref.n;
	*final = ref.final;
	trace_free(&ref);
	return 0;
}

static void cfg_kind(struct motion_config *c, int kind)
{
	motion_config_default(c);
	c->jerk_limited = kind == 1;
}

static int t_empty_program(void)
{
	static const char *const progs[] = { "", "M2\n", "(nothing)\n", "G21 G90\nM30\n" };
	for (int kind = 0; kind < 2; kind++)
		for (size_t i = 0; i < sizeof(progs) / sizeof(progs[0]); i++) {
			struct motion_config c;
			size_t n;
			enum motion_status st;
			cfg_kind(&c, kind);
			CHECK(same_all_ways(&c, progs[i], 0, &n, &st) == 0, "program %zu", i);
			CHECK(st == MOTION_ST_DONE, "program %zu ends %d", i, (int)st);
			CHECK(n == 1, "program %zu: %zu setpoints, expected only DONE", i, n);
		}
	return 0;
}

static int t_one_segment(void)
{
	static const char *const progs[] = {
		"G21 G90 F600\nG1 X1\nM2\n",   /* about 100 setpoints */
		"G21 G90 F600\nG1 X0.0004\nM2\n", /* shorter than one period's travel */
		"G21 G90\nG4 P0.0002\nM2\n",   /* a dwell shorter than a period */
		"G21 G90\nG4 P0.005\nM2\n",
	};
	for (int kind = 0; kind < 2; kind++)
		for (size_t i = 0; i < sizeof(progs) / sizeof(progs[0]); i++) {
			struct motion_config c;
			size_t n;
			enum motion_status st;
			cfg_kind(&c, kind);
			CHECK(same_all_ways(&c, progs[i], 0, &n, &st) == 0, "program %zu", i);
			CHECK(st == MOTION_ST_DONE, "program %zu ends %d", i, (int)st);
			CHECK(n >= 2, "program %zu: %zu setpoints", i, n);
		}
	return 0;
}

/* Many segments shorter than a chunk (1 um chords: one or two setpoints
 * each) and long lines (many chunks each). */
static int t_short_and_long_segments(void)
{
	char *prog = gen_program(300);
	static const char lines[] = "G21 G90 F3000\nG1 X20\nG1 Y5\nG1 X0 Y0\nM2\n";

	CHECK(prog, "oom");
	for (int kind = 0; kind < 2; kind++) {
		struct motion_config c;
		size_t n;
		enum motion_status st;
		cfg_kind(&c, kind);
		c.chord_tol = 0.001e-3 * 5;
		CHECK(same_all_ways(&c, prog, 0, &n, &st) == 0, "arcs");
		CHECK(st == MOTION_ST_DONE && n > 1000, "arcs: %zu setpoints, %d", n, (int)st);
		cfg_kind(&c, kind);
		CHECK(same_all_ways(&c, lines, 0, &n, &st) == 0, "lines");
		CHECK(st == MOTION_ST_DONE && n > 1000, "lines: %zu setpoints", n);
	}
	free(prog);
	return 0;
}

/* A fault part way: the motion accepted before it comes to rest. */
static int t_fault(void)
{
	static const char prog[] = "G21 G90 F1200\nG1 X1\nG1 X2 Y1\nG1 Q5\nG1 X3\n";
	for (int kind = 0; kind < 2; kind++) {
		struct motion_config c;
		size_t n;
		enum motion_status st;
		cfg_kind(&c, kind);
		CHECK(same_all_ways(&c, prog, 0, &n, &st) == 0, "fault");
		CHECK(st == MOTION_ST_FAULT && n > 10, "%zu setpoints, final %d", n, (int)st);
	}
	return 0;
}

/* Streamed in small pieces: the stream runs dry now and then, the
 * look-ahead plans to a stop and the interpolation may stop at rest; the
 * same feed gives the same setpoints whatever the lanes. */
static int t_streamed(void)
{
	char *prog = gen_program(200);

	CHECK(prog, "oom");
	for (int kind = 0; kind < 2; kind++) {
		struct motion_config c;
		size_t n;
		enum motion_status st;
		cfg_kind(&c, kind);
		CHECK(same_all_ways(&c, prog, 37, &n, &st) == 0, "streamed");
		CHECK(st == MOTION_ST_DONE && n > 1000, "%zu setpoints, final %d", n, (int)st);
	}
	free(prog);
	return 0;
}

/* ---- worker pool: the drain sink's hash against the synchronous run ---- */

static int sync_hash(const struct motion_config *c, const char *prog,
		     uint64_t *h, uint64_t *count)
{
	struct trace tr;

	*h = *count = 0;
	if (run_program(c, prog, 0, 50000000, &tr))
		return -1;
	for (size_t i = 0; i < tr.n; i++)
		if (tr.sp[i].status == MOTION_ST_MOVING) {
			*h = motion_setpoint_hash(*h, &tr.sp[i]);
			(*count)++;
		}
	int ok = tr.final == MOTION_ST_DONE;
	trace_free(&tr);
	return ok ? 0 : -1;
}

static int pool_hash(struct motion_config c, const char *prog, unsigned workers,
		     uint64_t *h, uint64_t *count, uint64_t lane_runs[2])
{
	struct motion *m;
	struct motion_error e;
	struct motion_stats s;

	c.drain_sink = true;
	if (motion_create(&c, &m, &e) || motion_load_program(m, prog, strlen(prog)) ||
	    motion_start(m, workers))
		return -1;
	int wrc = motion_wait(m, 120000u);
	motion_stop(m);
	motion_get_stats(m, &s);
	*h = motion_sink_checksum(m);
	*count = s.setpoints;
	lane_runs[0] = lane_runs[1] = 0;
	for (unsigned t = 0; t < s.n_tasks; t++)
		for (unsigned k = 0; k < 2; k++)
			if (!strcmp(s.task_name[t], k ? "interp1" : "interp0"))
				for (unsigned w = 0; w < MOTION_MAX_WORKERS; w++)
					lane_runs[k] += s.runs[t][w];
	bool ok = wrc == 0 && motion_done(m) && !motion_last_error(m);
	motion_destroy(m);
	return ok ? 0 : -1;
}

static int t_pool_matches_sync(void)
{
	const char *env = getenv("MOTION_LANES_BLOCKS"); /* shorter under sanitizers */
	char *prog = gen_program(env ? atoi(env) : 400);

	CHECK(prog, "oom");
	for (int kind = 0; kind < 2; kind++) {
		struct motion_config c;
		uint64_t h0, n0, h, n, runs[2];
		cfg_kind(&c, kind);
		c.chord_tol = 0.0002;
		c.batch = 64;
		CHECK(sync_hash(&c, prog, &h0, &n0) == 0, "sync run failed");
		for (uint32_t lanes = 1; lanes <= 3; lanes++)
			for (int pol = 0; pol < 2; pol++)
				for (unsigned w = 1; w <= 3; w++) {
					c.interp_lanes = lanes;
					c.interp_chunk = lanes == 3 ? 5 : 0;
					c.policy = pol ? MOTION_POLICY_FIFO : MOTION_POLICY_HYBRID;
					CHECK(pool_hash(c, prog, w, &h, &n, runs) == 0,
					      "pool run failed (%u lanes, %u workers)", lanes, w);
					CHECK(h == h0 && n == n0,
					      "%s, %u lanes, policy %d, %u workers: %llu setpoints hash %llx; sync %llu hash %llx",
					      kind ? "S-curve" : "trapezoid", lanes, pol, w,
					      (unsigned long long)n, (unsigned long long)h,
					      (unsigned long long)n0, (unsigned long long)h0);
					if (lanes >= 2)
						CHECK(runs[0] > 0 && runs[1] > 0,
						      "a lane never ran: %llu/%llu jobs",
						      (unsigned long long)runs[0],
						      (unsigned long long)runs[1]);
				}
		printf("  %s: %llu setpoints, the same from 1-3 lanes on 1-3 workers\n",
		       kind ? "S-curve" : "trapezoid", (unsigned long long)n0);
	}
	free(prog);
	return 0;
}

static int t_config(void)
{
	struct motion_config c;
	struct motion *m;
	struct motion_error e;
	struct motion_stats s;

	motion_config_default(&c);
	CHECK(c.interp_lanes == MOTION_DEFAULT_LANES, "default lanes %u", c.interp_lanes);
	c.interp_lanes = MOTION_MAX_WORKERS + 1;
	CHECK(motion_create(&c, &m, &e) != 0 && e.code == MOTION_E_CONFIG, "9 lanes accepted");
	c.interp_lanes = 0; /* the default */
	CHECK(motion_create(&c, &m, &e) == 0, "0 lanes refused: %s", e.msg);
	motion_get_stats(m, &s);
	unsigned lanes = 0, peaks = 0;
	for (unsigned t = 0; t < s.n_tasks; t++) {
		lanes += !strncmp(s.task_name[t], "interp", 6);
		peaks += !strncmp(s.task_name[t], "peak", 4);
	}
	CHECK(lanes == MOTION_DEFAULT_LANES, "%u lane tasks", lanes);
	CHECK(peaks == MOTION_DEFAULT_LANES, "%u profile lane tasks", peaks);
	motion_destroy(m);
	c.interp_lanes = MOTION_MAX_WORKERS;
	c.drain_sink = true;
	c.send_cb = NULL;
	c.trace_samples = 16;
	CHECK(motion_create(&c, &m, &e) == 0, "8 lanes refused: %s", e.msg);
	motion_get_stats(m, &s);
	/* decode, fit, look-ahead, accel, 8 profile lanes, 8 interpolation
	 * lanes, sink, monitor: every slot of the stats but one */
	CHECK(s.n_tasks == 4 + 2 * MOTION_MAX_WORKERS + 1 + 1, "%u tasks", s.n_tasks);
	CHECK(s.n_tasks < MOTION_N_TASKS, "%u tasks", s.n_tasks);
	motion_destroy(m);
	return 0;
}

static const struct test_case cases[] = {
	{ "config", t_config },
	{ "empty_program", t_empty_program },
	{ "one_segment", t_one_segment },
	{ "short_and_long_segments", t_short_and_long_segments },
	{ "fault", t_fault },
	{ "streamed", t_streamed },
	{ "pool_matches_sync", t_pool_matches_sync },
};

int main(int argc, char **argv)
{
	return test_main(argc, argv, cases, sizeof(cases) / sizeof(cases[0]));
}
