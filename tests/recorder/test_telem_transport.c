// SPDX-License-Identifier: MIT
/*
 * test_telem_transport - the telemetry transport without a network client:
 * exact drop counts, a producer that never waits (consumer absent), and
 * concurrent producers with the drain thread (run under TSan). The ring
 * itself is motion/ring.h, tested by motion/tests/test_ring.c.
 *
 *   test_telem_transport [N]   N = records for the threaded cases (default 2000000)
 */
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "servoamp/mono_clock.h"
#include "telem.h"

static int failed, passed;
#define CHECK(c) do { if (!(c)) { fprintf(stderr, "%s:%d: CHECK(%s) failed\n", __FILE__, __LINE__, #c); failed++; return; } } while (0)

/* The cycle thread's pace: a busy wait (no syscall besides the vDSO clock). */
static void spin_ns(uint64_t ns)
{
	uint64_t end = mono_now_ns() + ns;

	while (mono_now_ns() < end)
		;
}

static void cfg_local(struct telem_cfg *cfg, uint32_t ring)
{
	telem_cfg_defaults(cfg);
	cfg->listen_addr = "127.0.0.1";
	cfg->port = 0;
	cfg->n_axes = 8;
	cfg->ring_capacity = ring;
	cfg->event_capacity = 4;
}

/* The consumer never runs: every push after the ring filled is dropped and
 * counted exactly, and no push waits. */
static void test_push_never_blocks_without_consumer(unsigned long n)
{
	static struct telem t;
	struct telem_cfg cfg;
	struct telem_cycle rec;
	struct telem_stats st;
	unsigned long fails = 0;
	uint64_t t0, worst = 0, total;

	cfg_local(&cfg, 1024);
	CHECK(telem_init(&t, &cfg) == 0);
	memset(&rec, 0, sizeof(rec));
	rec.n_axes = 8;
	t0 = mono_now_ns();
	for (unsigned long i = 0; i < n; i++) {
		uint64_t a = mono_now_ns(), d;

		rec.cycle = i;
		if (telem_push_cycle(&t, &rec))
			fails++;
		d = mono_now_ns() - a;
		if (d > worst)
			worst = d;
	}
	total = mono_now_ns() - t0;
	telem_get_stats(&t, &st);
	printf("push without consumer: %lu pushes in %.1f ms, %.0f ns/push, worst %llu ns\n",
	       n, (double)total / 1e6, (double)total / (double)n, (unsigned long long)worst);
	CHECK(st.pushed == n);
	CHECK(fails == n - 1024);
	CHECK(st.dropped == n - 1024);
	/* events: bounded queue, drops counted */
	for (int i = 0; i < 10; i++)
		telem_push_log(&t, 0, TELEM_LOG_INFO, "test", "x", 1);
	telem_get_stats(&t, &st);
	CHECK(st.events == 4 && st.events_dropped == 6);
	telem_destroy(&t);
	passed++;
}

/* The real transport, drain thread running, no client: pushes from the
 * cycle thread and events from two other threads at once. */
struct tx {
	struct telem *t;
	unsigned long n;
};

static void *tx_cycles(void *arg)
{
	struct tx *x = arg;
	struct telem_cycle rec;

	memset(&rec, 0, sizeof(rec));
	rec.n_axes = 8;
	for (unsigned long i = 0; i < x->n; i++) {
		spin_ns(500);
		rec.cycle = i;
		rec.t_ns = i * 1000u;
		rec.cmd[0].target_pos = (int32_t)i;
		telem_push_cycle(x->t, &rec);
	}
	return NULL;
}

static void *tx_events(void *arg)
{
	struct tx *x = arg;

	for (unsigned long i = 0; i < x->n / 1000; i++) {
		struct telem_queue_level q = { "blocks", (uint32_t)i, 100 };

		telem_push_param(x->t, 0, 1, "p", TELEM_P_U32, (double)i, "");
		telem_push_log(x->t, 0, TELEM_LOG_DEBUG, "t", "line\n", 5);
		telem_push_queues(x->t, 0, &q, 1);
	}
	return NULL;
}

static void test_transport_threads(unsigned long n)
{
	static struct telem t;
	struct telem_cfg cfg;
	struct telem_stats st;
	struct tx x;
	pthread_t a, b, c;

	cfg_local(&cfg, 512);
	cfg.event_capacity = 64;
	cfg.drain_interval_us = 500;
	CHECK(telem_init(&t, &cfg) == 0);
	CHECK(telem_port(&t) != 0);
	CHECK(telem_start(&t) == 0);
	x.t = &t;
	x.n = n;
	pthread_create(&a, NULL, tx_cycles, &x);
	pthread_create(&b, NULL, tx_events, &x);
	pthread_create(&c, NULL, tx_events, &x);
	pthread_join(a, NULL);
	pthread_join(b, NULL);
	pthread_join(c, NULL);
	telem_stop(&t);
	telem_get_stats(&t, &st);
	printf("transport threads: pushed %llu drained %llu dropped %llu events %llu (+%llu dropped) hw %u\n",
	       (unsigned long long)st.pushed, (unsigned long long)st.drained,
	       (unsigned long long)st.dropped, (unsigned long long)st.events,
	       (unsigned long long)st.events_dropped, st.ring_high_water);
	CHECK(st.pushed == n);
	CHECK(st.drained + st.dropped == n);
	CHECK(st.events + st.events_dropped == 2 * 3 * (n / 1000));
	CHECK(st.ring_high_water <= 512);
	CHECK(st.drained > 512);
	telem_destroy(&t);
	passed++;
}

int main(int argc, char **argv)
{
	unsigned long n = argc > 1 ? strtoul(argv[1], NULL, 10) : 2000000ul;

	test_push_never_blocks_without_consumer(n);
	test_transport_threads(n / 4);
	printf("%d passed, %d failed\n", passed, failed);
	return failed ? 1 : 0;
}
