/* SPDX-License-Identifier: MIT */
/* The pipeline on worker threads: same setpoints as the synchronous run,
 * under every policy and worker count; and real-time service of the
 * periodic position-send task. */
#define _POSIX_C_SOURCE 200809L
#include <math.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "check.h"
#include "servoamp/mono_clock.h"

/* Many short arcs along a zigzag (planning heavy), a few lines. */
static char *gen_program(int n)
{
	size_t cap = (size_t)n * 64 + 64, len = 0;
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
		x += 0.5 * dir;
		len += (size_t)snprintf(p + len, cap - len, "G%d X%.3f R%.3f\n",
					i % 2 ? 2 : 3, x, i % 3 ? 0.4 : -0.3);
	}
	snprintf(p + len, cap - len, "M2\n");
	return p;
}

static int sync_checksum(const struct motion_config *c, const char *prog,
			 uint64_t *sum, uint64_t *count)
{
	struct motion *m;
	struct motion_error e;
	struct motion_setpoint sp;
	enum motion_status st;

	*sum = *count = 0;
	if (motion_create(c, &m, &e) || motion_load_program(m, prog, strlen(prog)))
		return -1;
	while ((st = motion_next_setpoint(m, &sp)) != MOTION_ST_DONE) {
		if (st == MOTION_ST_FAULT || st == MOTION_ST_UNDERRUN) {
			motion_destroy(m);
			return -1;
		}
		if (st != MOTION_ST_MOVING)
			continue;
		*sum = motion_setpoint_hash(*sum, &sp);
		(*count)++;
	}
	motion_destroy(m);
	return 0;
}

static int threaded_checksum(struct motion_config c, const char *prog,
			     unsigned workers, uint64_t *sum, uint64_t *count)
{
	struct motion *m;
	struct motion_error e;
	struct motion_stats s;

	c.drain_sink = true;
	if (motion_create(&c, &m, &e) || motion_load_program(m, prog, strlen(prog)) ||
	    motion_start(m, workers))
		return -1;
	int wrc = motion_wait(m, 60000u);
	motion_stop(m);
	motion_get_stats(m, &s);
	*sum = motion_sink_checksum(m);
	*count = s.setpoints;
	uint64_t w[2] = { 0, 0 };
	for (unsigned t = 0; t < s.n_tasks; t++)
		for (unsigned k = 0; k < 2; k++)
			w[k] += s.runs[t][k];
	printf("  %s %u worker(s): %llu setpoints, jobs per worker %llu/%llu\n",
	       c.policy == MOTION_POLICY_FIFO ? "fifo" : "hybrid", workers,
	       (unsigned long long)*count, (unsigned long long)w[0],
	       (unsigned long long)w[1]);
	bool ok = wrc == 0 && motion_done(m) && !motion_last_error(m);
	motion_destroy(m);
	return ok ? 0 : -1;
}

static int t_drain_matches_sync(void)
{
	struct motion_config c;
	char *prog = gen_program(1500);
	uint64_t s0, n0, s, n;

	CHECK(prog, "oom");
	motion_config_default(&c);
	CHECK(sync_checksum(&c, prog, &s0, &n0) == 0, "sync run failed");
	CHECK(n0 > 1000, "only %llu setpoints", (unsigned long long)n0);
	for (int pol = 0; pol < 2; pol++) {
		c.policy = pol ? MOTION_POLICY_FIFO : MOTION_POLICY_HYBRID;
		for (unsigned w = 1; w <= 2; w++) {
			CHECK(threaded_checksum(c, prog, w, &s, &n) == 0, "threaded run failed");
			CHECK(s == s0 && n == n0,
			      "policy %d, %u workers: %llu setpoints sum %llu; sync %llu sum %llu",
			      pol, w, (unsigned long long)n, (unsigned long long)s,
			      (unsigned long long)n0, (unsigned long long)s0);
		}
	}
	free(prog);
	return 0;
}

struct rec {
	struct trace tr;   /* preallocated: the callback must not allocate */
	atomic_size_t n;
	atomic_int last;
};

static void rec_cb(void *user, const struct motion_setpoint *sp)
{
	struct rec *r = user;
	size_t i = atomic_load(&r->n);

	if (i < r->tr.cap) {
		r->tr.sp[i] = *sp;
		atomic_store(&r->n, i + 1);
	}
	atomic_store(&r->last, sp->status);
}

static int t_realtime_send(void)
{
	struct motion_config c;
	struct motion *m;
	struct motion_error e;
	struct rec *r = calloc(1, sizeof(*r));
	char why[200];
	const char *prog = "G21 G90 F6000\nG1 X10 Y5\nG2 X20 Y5 I5 J0\nG1 X20 Y0\nG0 X0 Y0\nM2\n";

	CHECK(r, "oom");
	r->tr.cap = 20000;
	r->tr.sp = calloc(r->tr.cap, sizeof(*r->tr.sp));
	CHECK(r->tr.sp, "oom");
	motion_config_default(&c);
	c.increments_per_mm = 1e5;
	c.send_cb = rec_cb;
	c.send_user = r;
	c.trace_samples = 1000;
	c.monitor_period_us = 5000;
	CHECK(motion_create(&c, &m, &e) == 0, "%s", e.msg);
	CHECK(motion_load_program(m, prog, strlen(prog)) == 0, "load");
	uint64_t t0 = mono_now_us();
	CHECK(motion_start(m, 2) == 0, "start");
	while (atomic_load(&r->last) != MOTION_ST_DONE &&
	       atomic_load(&r->last) != MOTION_ST_FAULT &&
	       atomic_load(&r->last) != MOTION_ST_UNDERRUN &&
	       mono_now_us() - t0 < 20000000u) {
		struct timespec ts = { 0, 1000000 };
		nanosleep(&ts, NULL);
	}
	motion_stop(m);
	uint64_t el = mono_now_us() - t0; /* every send happened in it */
	r->tr.n = atomic_load(&r->n);
	struct motion_stats s;
	motion_get_stats(m, &s);
	printf("  %zu cycles sent in %.3f s (period %u us), underruns %llu\n", r->tr.n,
	       el / 1e6, c.period_us, (unsigned long long)s.underruns);
	CHECK(atomic_load(&r->last) == MOTION_ST_DONE, "status %d: %s", atomic_load(&r->last),
	      motion_last_error(m) ? motion_last_error(m)->msg : "-");
	CHECK(s.underruns == 0, "underruns");
	/* the send task is periodic: never more sends than periods elapsed
	 * (the first release is one period after the start). A loaded host
	 * can make it miss releases, which the run survives: the program
	 * above ended with every setpoint sent, checked below. */
	CHECK(r->tr.n <= el / c.period_us, "%zu sends in %llu us: faster than the %u us period",
	      r->tr.n, (unsigned long long)el, c.period_us);
	const struct motion_setpoint *lst = &r->tr.sp[r->tr.n - 1];
	CHECK(lst->pos[0] == 0 && lst->pos[1] == 0, "end %d %d", lst->pos[0], lst->pos[1]);
	CHECK(check_limits(&r->tr, &c, why, sizeof(why)) == 0, "%s", why);
	/* the monitor task sampled the queues */
	char *buf = NULL;
	size_t len = 0;
	FILE *f = open_memstream(&buf, &len);
	CHECK(f && motion_trace_csv(m, f) == 0, "trace");
	fclose(f);
	size_t lines = 0;
	for (size_t i = 0; i < len; i++)
		lines += buf[i] == '\n';
	CHECK(strncmp(buf, "t_us,stream_bytes,blocks", 24) == 0 && lines > 10,
	      "trace has %zu lines", lines);
	free(buf);
	motion_destroy(m);
	trace_free(&r->tr);
	free(r);
	return 0;
}

/* motion_wait(): returns when the run has ended (every setpoint taken, or a
 * fault), on time-out without an end, and never in synchronous mode. */
static int t_wait(void)
{
	struct motion_config c;
	struct motion *m;
	struct motion_error e;
	struct motion_setpoint sp;
	char *prog = gen_program(300);

	CHECK(prog, "oom");
	motion_config_default(&c);

	/* synchronous mode: nothing to wait for */
	CHECK(motion_create(&c, &m, &e) == 0, "create: %s", e.msg);
	CHECK(motion_load_program(m, prog, strlen(prog)) == 0, "load");
	CHECK(motion_wait(m, 10) == -1, "wait in synchronous mode must fail");
	motion_destroy(m);

	/* the sink takes every setpoint: wait returns once it has */
	c.drain_sink = true;
	CHECK(motion_create(&c, &m, &e) == 0, "create: %s", e.msg);
	CHECK(motion_load_program(m, prog, strlen(prog)) == 0, "load");
	CHECK(motion_start(m, 2) == 0, "start");
	CHECK(motion_wait(m, 60000u) == 0, "no end within 60 s");
	CHECK(motion_done(m) && !motion_last_error(m), "ended but not done");
	motion_stop(m);
	motion_destroy(m);

	/* a stream that is never closed: the run cannot end, wait times out */
	CHECK(motion_create(&c, &m, &e) == 0, "create: %s", e.msg);
	CHECK(motion_stream_write(m, "G1 X1 F600\n", 11) == 11, "write");
	uint64_t t0 = mono_now_us();
	CHECK(motion_start(m, 2) == 0, "start");
	CHECK(motion_wait(m, 50) == -1, "wait returned 0 on an open stream");
	uint64_t dt = mono_now_us() - t0;
	CHECK(dt >= 45000u, "timed out after %llu us, asked 50 ms",
	      (unsigned long long)dt);
	CHECK(!motion_done(m), "done with an open stream");
	motion_stop(m);
	motion_destroy(m);

	/* a fault ends the run: wait returns and the error is there */
	static const char bad[] = "G21 G90 F600\nG1 X1\nG1 X2 Q\nG1 X3\n";
	CHECK(motion_create(&c, &m, &e) == 0, "create: %s", e.msg);
	CHECK(motion_load_program(m, bad, strlen(bad)) == 0, "load");
	CHECK(motion_start(m, 2) == 0, "start");
	CHECK(motion_wait(m, 60000u) == 0, "no end after a fault within 60 s");
	CHECK(motion_last_error(m) && motion_last_error(m)->line == 3,
	      "expected the error on line 3");
	motion_stop(m);
	/* the consumer still gets safe setpoints */
	(void)motion_next_setpoint(m, &sp);
	motion_destroy(m);
	free(prog);
	return 0;
}

/* config.min_job: 0..4096 accepted (0 = batch, 1 = rule 2 as written),
 * above refused with a configuration error that names it. */
static int t_min_job_config(void)
{
	struct motion_config c;
	struct motion *m;
	struct motion_error e;
	const uint32_t ok[] = { 0, 1, 4096 };

	motion_config_default(&c);
	for (size_t i = 0; i < sizeof(ok) / sizeof(ok[0]); i++) {
		c.min_job = ok[i];
		CHECK(motion_create(&c, &m, &e) == 0, "min_job %u refused: %s", ok[i], e.msg);
		motion_destroy(m);
	}
	c.min_job = 4097;
	m = NULL;
	CHECK(motion_create(&c, &m, &e) != 0 && m == NULL, "min_job 4097 accepted");
	CHECK(e.code == MOTION_E_CONFIG && strstr(e.msg, "min_job"), "error: %d %s", e.code, e.msg);
	return 0;
}

static const struct test_case cases[] = {
	{ "wait", t_wait },
	{ "min_job_config", t_min_job_config },
	{ "drain_matches_sync", t_drain_matches_sync },
	{ "realtime_send", t_realtime_send },
};

int main(int argc, char **argv)
{
	return test_main(argc, argv, cases, sizeof(cases) / sizeof(cases[0]));
}
