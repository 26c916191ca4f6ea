// SPDX-License-Identifier: MIT
/*
 * telem_push.c - the producers: telem_push_cycle (the real-time cycle
 * thread, into the ring) and the events telem_push_param / _log / _gap /
 * _queues (any thread, into the mutex-protected event queue), and
 * telem_get_stats.
 */
#define _GNU_SOURCE
#include "telem_internal.h"

#include <pthread.h>

/* ---- producers ---------------------------------------------------------------- */
int telem_push_cycle(struct telem *t, const struct telem_cycle *rec)
{
	uint64_t seq = t->push_seq++;
	struct telem_slot *s;

	atomic_store_explicit(&t->pushed, t->push_seq, memory_order_seq_cst);	/* app_seq */
	atomic_store_explicit(&t->last_cycle, rec->cycle, memory_order_relaxed);
	s = ring_slot(&t->ring);
	if (!s) {
		t->drop_local++;
		atomic_store_explicit(&t->dropped, t->drop_local, memory_order_seq_cst);
		return -1;
	}
	s->seq = seq;
	s->c = *rec;
	ring_commit(&t->ring);
	return 0;
}

static int push_event(struct telem *t, const unsigned char *data, uint32_t len)
{
	int rc = 0;

	pthread_mutex_lock(&t->ev_lock);
	if (t->ev_head - t->ev_tail >= t->ev_cap) {
		atomic_fetch_add_explicit(&t->events_dropped, 1u, memory_order_relaxed);
		rc = -1;
	} else {
		struct telem_event *e = &t->ev[t->ev_head % t->ev_cap];

		e->len = len;
		memcpy(e->data, data, len);
		t->ev_head++;
		atomic_fetch_add_explicit(&t->events, 1u, memory_order_relaxed);
	}
	pthread_mutex_unlock(&t->ev_lock);
	return rc;
}

static uint64_t now_or(uint64_t t_ns)
{
	return t_ns ? t_ns : mono_now_ns();
}

int telem_push_param(struct telem *t, uint64_t t_ns, uint32_t id, const char *name,
		     uint32_t type, double value, const char *unit)
{
	unsigned char b[FRAME_HDR + PARAM_LEN], *p = b;

	p = frame(p, TELEM_MSG_PARAM, PARAM_LEN);
	p = put64(p, now_or(t_ns));
	p = put64(p, atomic_load_explicit(&t->last_cycle, memory_order_relaxed));
	p = put32(p, id);
	p = put32(p, type);
	p = putf64(p, value);
	p = putstr(p, name, TELEM_NAME_LEN);
	p = putstr(p, unit, TELEM_UNIT_LEN);
	return push_event(t, b, (uint32_t)(p - b));
}

int telem_push_log(struct telem *t, uint64_t t_ns, uint32_t level, const char *source,
		   const char *text, size_t len)
{
	unsigned char b[EVENT_MAX], *p = b;

	if (!text)
		len = 0;
	if (len > TELEM_LOG_MAX)
		len = TELEM_LOG_MAX;
	while (len && (text[len - 1] == '\n' || text[len - 1] == '\r'))
		len--;
	p = frame(p, TELEM_MSG_LOG, LOG_HDR_LEN + (uint32_t)len);
	p = put64(p, now_or(t_ns));
	p = put64(p, atomic_load_explicit(&t->last_cycle, memory_order_relaxed));
	p = put32(p, level);
	p = put32(p, (uint32_t)len);
	p = putstr(p, source, TELEM_SOURCE_LEN);
	if (len)
		memcpy(p, text, len);
	p += len;
	return push_event(t, b, (uint32_t)(p - b));
}

int telem_push_gap(struct telem *t, uint64_t t_ns, uint64_t from_cycle, uint64_t to_cycle,
		   uint64_t count, uint32_t reason)
{
	unsigned char b[FRAME_HDR + GAP_LEN];

	telem__enc_gap(b, now_or(t_ns), from_cycle, to_cycle, count, reason);
	return push_event(t, b, sizeof(b));
}

int telem_push_queues(struct telem *t, uint64_t t_ns, const struct telem_queue_level *q,
		      unsigned n)
{
	unsigned char b[EVENT_MAX], *p = b;

	if (n > TELEM_MAX_QUEUES)
		n = TELEM_MAX_QUEUES;
	p = frame(p, TELEM_MSG_QUEUES, QUEUES_HDR_LEN + QUEUE_LEN * n);
	p = put64(p, now_or(t_ns));
	p = put32(p, n);
	p = put32(p, 0);
	for (unsigned i = 0; i < n; i++) {
		p = putstr(p, q[i].name, TELEM_QUEUE_NAME_LEN);
		p = put32(p, q[i].level);
		p = put32(p, q[i].capacity);
	}
	return push_event(t, b, (uint32_t)(p - b));
}

void telem_get_stats(struct telem *t, struct telem_stats *st)
{
	memset(st, 0, sizeof(*st));
	/* seq_cst: in one order with an application's seqcount (app_seq) */
	st->pushed = atomic_load_explicit(&t->pushed, memory_order_seq_cst);
	st->dropped = atomic_load_explicit(&t->dropped, memory_order_seq_cst);
	st->drained = atomic_load_explicit(&t->drained, memory_order_relaxed);
	st->events = atomic_load_explicit(&t->events, memory_order_relaxed);
	st->events_dropped = atomic_load_explicit(&t->events_dropped, memory_order_relaxed);
	st->client_lost = atomic_load_explicit(&t->client_lost, memory_order_relaxed);
	st->bytes_sent = atomic_load_explicit(&t->bytes_sent, memory_order_relaxed);
	st->clients_total = atomic_load_explicit(&t->clients_total, memory_order_relaxed);
	st->clients = atomic_load_explicit(&t->clients_now, memory_order_relaxed);
	st->ring_high_water = atomic_load_explicit(&t->ring_high_water, memory_order_relaxed);
	st->auth_failed = atomic_load_explicit(&t->drop_auth_failed, memory_order_relaxed);
	st->auth_timeout = atomic_load_explicit(&t->drop_auth_timeout, memory_order_relaxed);
	st->evicted = atomic_load_explicit(&t->drop_evicted, memory_order_relaxed);
	st->refused = atomic_load_explicit(&t->drop_refused, memory_order_relaxed);
	st->stalled = atomic_load_explicit(&t->drop_stalled, memory_order_relaxed);
	st->protocol = atomic_load_explicit(&t->drop_protocol, memory_order_relaxed);
}
