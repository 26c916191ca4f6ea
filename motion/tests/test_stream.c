/* SPDX-License-Identifier: MIT */
/*
 * Streaming: a long program, generated on the fly, goes through the
 * XOFF/XON flow control in bounded memory.  Line count from the
 * environment (MOTION_STREAM_LINES, default 1000000; the threaded case
 * uses MOTION_STREAM_THREADED_LINES, default 100000).
 */
#define _POSIX_C_SOURCE 200809L
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "check.h"
#include "servoamp/mono_clock.h"

static long rss_kib(void)
{
	FILE *f = fopen("/proc/self/status", "r");
	char line[256];
	long v = -1;

	if (!f)
		return -1;
	while (fgets(line, sizeof(line), f))
		if (strncmp(line, "VmRSS:", 6) == 0)
			v = atol(line + 6);
	fclose(f);
	return v;
}

static unsigned long env_lines(const char *name, unsigned long def)
{
	const char *v = getenv(name);
	return v && *v ? strtoul(v, NULL, 10) : def;
}

/* The generated program: back and forth along X in 0.05 mm steps over
 * 0..50 mm with a comment and line numbers now and then, a few arcs. */
struct gen {
	unsigned long n, i;
	long x;   /* position in 0.05 mm units */
	int dir;
	long y;   /* 0 or 10 mm (arcs flip it) */
};

static size_t gen_line(struct gen *g, char *buf, size_t cap)
{
	unsigned long i = g->i++;

	if (i == 0)
		return (size_t)snprintf(buf, cap, "G21 G90 G17 F6000 (streamed program)\n");
	if (i == g->n - 1)
		return (size_t)snprintf(buf, cap, "M2\n");
	if (i % 5000 == 0) { /* a half circle to the other y */
		long ny = g->y ? 0 : 10;
		size_t l = (size_t)snprintf(buf, cap, "G%d X%.2f Y%ld R5 F3000\n",
					    g->y ? 3 : 2, g->x * 0.05, ny);
		g->y = ny;
		return l;
	}
	g->x += g->dir;
	if (g->x >= 1000 || g->x <= 0)
		g->dir = -g->dir;
	if (i % 1000 == 0)
		return (size_t)snprintf(buf, cap, "N%lu G1 X%.2f Y%ld F6000 ; step\n", i,
					g->x * 0.05, g->y);
	return (size_t)snprintf(buf, cap, "G1 X%.2f\n", g->x * 0.05);
}

struct flowlog {
	struct motion *m;
	uint32_t high, low;
	atomic_uint bad;     /* XOFF below high or XON above low */
	atomic_uint xoff, xon;
};

static void flow_cb(void *user, enum motion_flow ev)
{
	struct flowlog *fl = user;
	/* the level that decided this event (the live one may already have
	 * moved: the writer and the decoder run concurrently when threaded) */
	uint32_t lvl = motion_stream_event_level(fl->m);

	if (ev == MOTION_FLOW_XOFF) {
		atomic_fetch_add(&fl->xoff, 1);
		if (lvl < fl->high)
			atomic_fetch_add(&fl->bad, 1);
	} else {
		atomic_fetch_add(&fl->xon, 1);
		if (lvl > fl->low)
			atomic_fetch_add(&fl->bad, 1);
	}
}

static int stream_run(bool threaded, unsigned long n)
{
	struct motion_config c;
	struct motion *m;
	struct motion_error err;
	struct flowlog fl;
	struct gen g = { n, 0, 0, 1, 0 };
	char chunk[4096];
	size_t have = 0, off = 0;
	long rss_early = -1, rss_peak = 0;
	uint64_t t0 = mono_now_us(), cycles = 0;
	enum motion_status st = MOTION_ST_IDLE;

	motion_config_default(&c);
	c.increments_per_mm = 1000;
	c.flow_cb = flow_cb;
	c.flow_user = &fl;
	c.drain_sink = threaded;
	memset(&fl, 0, sizeof(fl));
	fl.high = c.stream_high;
	fl.low = c.stream_low;
	CHECK(motion_create(&c, &m, &err) == 0, "%s", err.msg);
	fl.m = m;
	if (threaded)
		CHECK(motion_start(m, 2) == 0, "start");
	bool ended = false;
	uint32_t max_level = 0;
	for (;;) {
		/* the host: one chunk per cycle while XON */
		if (!ended && motion_stream_flow(m) == MOTION_FLOW_XON) {
			if (off == have) {
				have = off = 0;
				while (g.i < g.n && have < sizeof(chunk) - 128)
					have += gen_line(&g, chunk + have, sizeof(chunk) - have);
			}
			if (have == 0) {
				motion_stream_end(m);
				ended = true;
			} else {
				long w = motion_stream_write(m, chunk + off, have - off);
				CHECK(w >= 0, "write refused: %s",
				      motion_last_error(m) ? motion_last_error(m)->msg : "?");
				off += (size_t)w;
			}
			uint32_t lvl = motion_stream_level(m);
			if (lvl > max_level)
				max_level = lvl;
		}
		if (threaded) {
			struct timespec ts = { 0, 50000 };
			if (motion_stream_flow(m) == MOTION_FLOW_XOFF || ended)
				nanosleep(&ts, NULL);
			if (motion_done(m)) {
				st = motion_last_error(m) ? MOTION_ST_FAULT : MOTION_ST_DONE;
				break;
			}
		} else {
			struct motion_setpoint sp;
			st = motion_next_setpoint(m, &sp);
			cycles++;
			if (st == MOTION_ST_DONE || st == MOTION_ST_FAULT ||
			    st == MOTION_ST_UNDERRUN)
				break;
		}
		if (rss_early < 0 && g.i >= n / 10)
			rss_early = rss_kib();
		if ((g.i & 0x3fff) == 0) {
			long r = rss_kib();
			rss_peak = r > rss_peak ? r : rss_peak;
		}
		CHECK(mono_now_us() - t0 < 120000000u, "timeout");
	}
	long rss_end = rss_kib();
	rss_peak = rss_end > rss_peak ? rss_end : rss_peak;
	if (threaded)
		motion_stop(m);
	struct motion_stats s;
	motion_get_stats(m, &s);
	double secs = (mono_now_us() - t0) / 1e6;
	printf("  %s: %llu lines, %llu segments, %llu setpoints in %.2f s; xoff %llu xon %llu;"
	       " stream peak %u/%u bytes (high %u); RSS %ld KiB at 10%%, %ld KiB peak, %ld KiB end\n",
	       threaded ? "threaded" : "sync", (unsigned long long)s.lines,
	       (unsigned long long)s.segments, (unsigned long long)s.setpoints, secs,
	       (unsigned long long)s.xoff_events, (unsigned long long)s.xon_events,
	       s.peak[0], s.cap[0], c.stream_high, rss_early, rss_peak, rss_end);
	printf("  peak queue levels:");
	for (unsigned q = 0; q < MOTION_N_QUEUES; q++)
		printf(" %s %u/%u", motion_queue_name(q), s.peak[q], s.cap[q]);
	printf("\n");
	CHECK(st == MOTION_ST_DONE, "ended with %d: %s", (int)st,
	      motion_last_error(m) ? motion_last_error(m)->msg : "-");
	CHECK(s.lines == n, "decoded %llu of %lu lines", (unsigned long long)s.lines, n);
	CHECK(s.underruns == 0, "underruns");
	/* watermarks: XOFF at >= high, XON at <= low, alternating */
	CHECK(atomic_load(&fl.bad) == 0, "%u flow events at the wrong level", atomic_load(&fl.bad));
	CHECK(s.xoff_events >= 1 && (s.xon_events == s.xoff_events ||
				     s.xon_events + 1 == s.xoff_events),
	      "xoff %llu xon %llu", (unsigned long long)s.xoff_events,
	      (unsigned long long)s.xon_events);
	CHECK(n < 100000 || s.xoff_events > 10, "flow control hardly used");
	/* bounded memory: the host overshoots the high mark by at most one
	 * write; every queue stays within its capacity */
	CHECK(s.peak[0] <= c.stream_high + sizeof(chunk) && s.peak[0] <= s.cap[0],
	      "stream peak %u", s.peak[0]);
	for (unsigned q = 1; q < MOTION_N_QUEUES; q++)
		CHECK(s.peak[q] <= s.cap[q], "queue %u over capacity", q);
	/* RSS does not grow with program length (allow 1 MiB of noise) */
	if (rss_early > 0 && n >= 100000)
		CHECK(rss_peak - rss_early < 1024, "RSS grew from %ld to %ld KiB", rss_early,
		      rss_peak);
	motion_destroy(m);
	return 0;
}

static int t_stream_sync(void)
{
	return stream_run(false, env_lines("MOTION_STREAM_LINES", 1000000));
}

static int t_stream_threaded(void)
{
	return stream_run(true, env_lines("MOTION_STREAM_THREADED_LINES", 100000));
}

static const struct test_case cases[] = {
	{ "stream_sync", t_stream_sync },
	{ "stream_threaded", t_stream_threaded },
};

int main(int argc, char **argv)
{
	return test_main(argc, argv, cases, sizeof(cases) / sizeof(cases[0]));
}
