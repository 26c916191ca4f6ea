/* SPDX-License-Identifier: MIT */
/*
 * The SPSC ring (motion/ring.h) on its own: argument checks, order,
 * a full ring that refuses without waiting, wrap-around, caller storage,
 * reset, the peak, and a producer and a consumer on two threads with
 * drops (run under TSan too). Its users: the motion pipeline, servod's
 * setpoint queue, the telemetry transport.
 *
 *   MOTION_RING_ITEMS  items of the threaded case (default 1000000)
 */
#define _POSIX_C_SOURCE 200809L
#include <pthread.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "check.h"
#include "motion/ring.h"
#include "servoamp/mono_clock.h"

static int t_init_rejects(void)
{
	struct ring r;

	CHECK(ring_init(&r, 8, 0) != 0, "cap 0");
	CHECK(ring_init(&r, 0, 8) != 0, "elem 0");
	CHECK(ring_init(&r, 8, (1u << 30) + 1u) != 0, "cap too large");
	CHECK(ring_init(&r, 8, 6) == 0, "cap 6");
	CHECK(r.cap == 6 && r.mask == 7, "cap %u mask %u", r.cap, r.mask);
	ring_free(&r);
	CHECK(r.buf == NULL, "freed");
	return 0;
}

static int t_order_full_wrap(void)
{
	struct ring r;
	uint64_t v = 0;
	const uint64_t *p;

	CHECK(ring_init(&r, sizeof(uint64_t), 8) == 0, "init");
	CHECK(ring_front(&r) == NULL, "empty");
	for (uint64_t i = 0; i < 8; i++) {
		uint64_t *s = ring_slot(&r);

		CHECK(s != NULL, "slot %llu", (unsigned long long)i);
		*s = i;
		ring_commit(&r);
	}
	CHECK(ring_count(&r) == 8 && ring_room(&r) == 0, "count %u", ring_count(&r));
	CHECK(ring_slot(&r) == NULL, "full: no slot, no wait");
	CHECK(!ring_push(&r, &v), "full: push refused");
	for (int k = 0; k < 3; k++) {
		p = ring_front(&r);
		CHECK(p && *p == v, "front %d", k);
		v++;
		ring_release(&r);
	}
	/* wrap around the indices many times */
	for (uint64_t i = 8; i < 100000; i++) {
		uint64_t out;

		CHECK(ring_push(&r, &i), "push %llu", (unsigned long long)i);
		CHECK(ring_pop(&r, &out) && out == v, "pop %llu", (unsigned long long)v);
		v++;
	}
	while ((p = ring_front(&r)) != NULL) {
		CHECK(*p == v, "drain %llu", (unsigned long long)v);
		v++;
		ring_release(&r);
	}
	CHECK(v == 100000, "v %llu", (unsigned long long)v);
	CHECK(atomic_load(&r.peak) == 8, "peak %u", atomic_load(&r.peak));
	ring_free(&r);
	return 0;
}

struct big {
	uint64_t seq;
	int32_t pad[13];	/* 60 bytes: one cache line a slot */
};

static int t_caller_storage(void)
{
	static _Alignas(RING_CACHELINE) unsigned char buf[RING_BUF_BYTES(sizeof(struct big), 16)];
	struct ring r;
	struct big b = { 0 };
	const struct big *p;

	CHECK(RING_STRIDE(sizeof(struct big)) == RING_CACHELINE, "stride");
	CHECK(RING_STRIDE(sizeof(uint32_t)) == sizeof(uint32_t), "small items pack");
	CHECK(ring_init_buf(&r, buf, sizeof(buf) - 1, sizeof(struct big), 16) != 0, "too small");
	CHECK(ring_init_buf(&r, buf + 4, sizeof(buf) - 4, sizeof(struct big), 8) != 0, "misaligned");
	CHECK(ring_init_buf(&r, NULL, sizeof(buf), sizeof(struct big), 16) != 0, "no storage");
	CHECK(ring_init_buf(&r, buf, sizeof(buf), sizeof(struct big), 16) == 0, "init");
	for (uint64_t i = 0; i < 16; i++) {
		b.seq = i;
		CHECK(ring_push(&r, &b), "push %llu", (unsigned long long)i);
	}
	CHECK(!ring_push(&r, &b), "full");
	p = ring_front(&r);
	CHECK(p == (const void *)buf && p->seq == 0, "first item at the start of the caller's storage");
	ring_reset(&r);
	CHECK(ring_count(&r) == 0 && ring_front(&r) == NULL, "reset empties it");
	CHECK(atomic_load(&r.peak) == 0, "reset clears the peak");
	for (uint64_t i = 100; i < 116; i++) {
		b.seq = i;
		CHECK(ring_push(&r, &b), "push after reset");
	}
	for (uint64_t i = 100; i < 116; i++) {
		p = ring_front(&r);
		CHECK(p && p->seq == i, "order after reset");
		ring_release(&r);
	}
	ring_free(&r);	/* the caller's storage: nothing to free */
	CHECK(r.buf == NULL, "forgotten");
	return 0;
}

/* Two threads: a producer at a steady pace that drops when the ring is
 * full, a consumer that stalls now and then; the consumer sees a strictly
 * increasing sequence whose holes add up to at most the drop count. */
struct spsc {
	struct ring r;
	unsigned long n;
	_Atomic int done;
	unsigned long dropped;
	unsigned long received, holes, disorder;
};

static void *spsc_producer(void *arg)
{
	struct spsc *s = arg;

	for (unsigned long i = 0; i < s->n; i++) {
		uint64_t end = mono_now_ns() + 150, *slot;

		while (mono_now_ns() < end)
			;	/* the cycle thread's pace */
		slot = ring_slot(&s->r);
		if (!slot) {
			s->dropped++;
			continue;
		}
		*slot = i;
		ring_commit(&s->r);
	}
	atomic_store(&s->done, 1);
	return NULL;
}

static void *spsc_consumer(void *arg)
{
	struct spsc *s = arg;
	uint64_t expect = 0;
	unsigned long k = 0;

	for (;;) {
		const uint64_t *p = ring_front(&s->r);

		if (!p) {
			if (atomic_load(&s->done) && ring_count(&s->r) == 0)
				break;
			continue;
		}
		if (*p < expect)
			s->disorder++;
		else
			s->holes += *p - expect;
		expect = *p + 1;
		s->received++;
		ring_release(&s->r);
		if (++k % 50000 == 0)	/* the non-RT thread is preempted */
			nanosleep(&(struct timespec){ .tv_nsec = 1000000 }, NULL);
	}
	return NULL;
}

static int t_spsc_threads(void)
{
	static struct spsc s;
	const char *env = getenv("MOTION_RING_ITEMS");
	pthread_t p, c;

	memset(&s, 0, sizeof(s));
	CHECK(ring_init(&s.r, sizeof(uint64_t), 256) == 0, "init");
	s.n = env ? strtoul(env, NULL, 10) : 1000000ul;
	pthread_create(&c, NULL, spsc_consumer, &s);
	pthread_create(&p, NULL, spsc_producer, &s);
	pthread_join(p, NULL);
	pthread_join(c, NULL);
	ring_free(&s.r);
	CHECK(s.disorder == 0, "out of order %lu", s.disorder);
	CHECK(s.received + s.dropped == s.n, "received %lu dropped %lu of %lu", s.received, s.dropped, s.n);
	/* drops after the last received item are not holes */
	CHECK(s.dropped >= s.holes, "holes %lu dropped %lu", s.holes, s.dropped);
	CHECK(s.received > 256, "the consumer ran concurrently (%lu)", s.received);
	return 0;
}

static const struct test_case cases[] = {
	{ "init_rejects", t_init_rejects },
	{ "order_full_wrap", t_order_full_wrap },
	{ "caller_storage", t_caller_storage },
	{ "spsc_threads", t_spsc_threads },
};

int main(int argc, char **argv)
{
	return test_main(argc, argv, cases, sizeof(cases) / sizeof(cases[0]));
}
