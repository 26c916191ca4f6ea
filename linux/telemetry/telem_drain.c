// SPDX-License-Identifier: MIT
/*
 * telem_drain.c - the drain thread: the cycle ring and the event queue
 * to every client, the periodic and final STATS, the poll of the
 * listening socket and the clients, the last drain and linger at the end;
 * telem_start and telem_stop.
 */
#define _GNU_SOURCE
#include "telem_internal.h"

#include <errno.h>
#include <poll.h>
#include <pthread.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

/* ---- drain thread: messages -------------------------------------------------------- */
static void drain_ring(struct telem *t)
{
	const struct telem_slot *s;
	uint32_t level = ring_count(&t->ring);

	if (level > atomic_load_explicit(&t->ring_high_water, memory_order_relaxed))
		atomic_store_explicit(&t->ring_high_water, level, memory_order_relaxed);
	while ((s = ring_front(&t->ring)) != NULL) {
		uint64_t seq = s->seq, cyc = s->c.cycle, t_ns = s->c.t_ns;
		size_t n = telem__enc_cycle(t, t->scratch, &s->c);

		ring_release(&t->ring);
		atomic_fetch_add_explicit(&t->drained, 1u, memory_order_relaxed);
		if (seq != t->expect_seq) {
			/* records expect_seq .. seq-1 were dropped by the producer */
			uint64_t lost = seq - t->expect_seq;
			uint64_t from = t->have_prev ? t->prev_cycle + 1u : cyc - lost;

			telem__broadcast_ring_gap(t, t_ns, from, cyc - 1u, lost);
		}
		t->expect_seq = seq + 1u;
		t->prev_cycle = cyc;
		t->have_prev = 1;
		telem__broadcast(t, t->scratch, n, &cyc, t_ns);
	}
}

static void drain_events(struct telem *t)
{
	for (;;) {
		struct telem_event *e;
		uint64_t t_ns;

		pthread_mutex_lock(&t->ev_lock);
		if (t->ev_tail == t->ev_head) {
			pthread_mutex_unlock(&t->ev_lock);
			return;
		}
		e = &t->ev[t->ev_tail % t->ev_cap];
		/* copy out under the lock: producers may reuse the slot after */
		memcpy(t->scratch, e->data, e->len);
		{
			uint32_t len = e->len;

			t->ev_tail++;
			pthread_mutex_unlock(&t->ev_lock);
			memcpy(&t_ns, t->scratch + FRAME_HDR, 8);
			telem__broadcast(t, t->scratch, len, NULL, t_ns);
		}
	}
}

static void send_stats(struct telem *t, uint32_t flags)
{
	struct telem_counter ctr[TELEM_MAX_COUNTERS];
	unsigned nc = 0;
	unsigned char b[STATS_MAX];
	struct telem_stats st;
	uint64_t now = mono_now_ns();

	memset(ctr, 0, sizeof(ctr));
	for (unsigned tries = 1;; tries++) {
		uint64_t seq = t->cfg.app_seq ? t->cfg.app_seq(t->cfg.app_arg) : 0;
		struct timespec pause = { 0, 20000 };

		if (t->cfg.app_counters) {
			nc = t->cfg.app_counters(t->cfg.app_arg, ctr, TELEM_MAX_COUNTERS);
			if (nc > TELEM_MAX_COUNTERS)
				nc = TELEM_MAX_COUNTERS;
		}
		telem_get_stats(t, &st);
		if (!t->cfg.app_seq || tries >= TELEM_SNAPSHOT_TRIES)
			break;
		if (!(seq & 1u) && t->cfg.app_seq(t->cfg.app_arg) == seq)
			break;
		nanosleep(&pause, NULL);	/* a cycle is under way: let it finish */
	}
	for (unsigned i = 0; i < TELEM_MAX_CLIENTS; i++) {
		struct telem_client *c = &t->clients[i];
		unsigned char *p;

		if (!live(c))
			continue;
		p = frame(b, TELEM_MSG_STATS, STATS_HDR_LEN + COUNTER_LEN * nc);
		p = put64(p, now);
		p = put64(p, t->prev_cycle);
		p = put64(p, st.pushed);
		p = put64(p, st.dropped);
		p = put64(p, st.drained);
		p = put64(p, c->lost_total);
		p = put64(p, c->events_lost);
		p = put64(p, st.events);
		p = put64(p, st.events_dropped);
		p = put64(p, st.bytes_sent);
		p = put32(p, st.ring_high_water);
		p = put32(p, t->cfg.ring_capacity);
		p = put32(p, st.clients);
		p = put32(p, flags);
		p = put32(p, nc);
		p = put32(p, 0);
		for (unsigned k = 0; k < nc; k++) {
			p = putstr(p, ctr[k].name, TELEM_COUNTER_NAME_LEN);
			p = put64(p, ctr[k].value);
		}
		telem__client_put(t, c, b, (size_t)(p - b), NULL, now);
	}
}

static int poll_clients(struct telem *t, int timeout_ms)
{
	struct pollfd pfd[2 + TELEM_MAX_CLIENTS];
	int idx[TELEM_MAX_CLIENTS];
	unsigned n = 0;
	int rc;

	pfd[n].fd = t->listen_fd;
	pfd[n++].events = POLLIN;
	pfd[n].fd = t->wake_fd[0];
	pfd[n++].events = POLLIN;
	for (unsigned i = 0; i < TELEM_MAX_CLIENTS; i++) {
		struct telem_client *c = &t->clients[i];

		idx[i] = -1;
		if (c->fd < 0)
			continue;
		idx[i] = (int)n;
		pfd[n].fd = c->fd;
		pfd[n++].events = (short)(POLLIN | (c->off < c->len ? POLLOUT : 0));
	}
	rc = poll(pfd, n, timeout_ms);
	if (rc <= 0)
		return rc;
	if (pfd[1].revents & POLLIN) {
		char sink[64];

		while (read(t->wake_fd[0], sink, sizeof(sink)) > 0)
			;
	}
	if (pfd[0].revents & POLLIN)
		telem__accept_clients(t);
	for (unsigned i = 0; i < TELEM_MAX_CLIENTS; i++)
		if (idx[i] >= 0 && (pfd[idx[i]].revents & (POLLIN | POLLHUP | POLLERR)))
			telem__client_read(t, &t->clients[i]);
	return rc;
}

static void flush_all(struct telem *t)
{
	for (unsigned i = 0; i < TELEM_MAX_CLIENTS; i++)
		telem__client_flush(t, &t->clients[i]);
}

static int pending(struct telem *t)
{
	for (unsigned i = 0; i < TELEM_MAX_CLIENTS; i++)
		if (live(&t->clients[i]) && t->clients[i].off < t->clients[i].len)
			return 1;
	return 0;
}

static void *drain_main(void *arg)
{
	struct telem *t = arg;
	int tick_ms = (int)(t->cfg.drain_interval_us / 1000u);
	uint64_t next_stats = mono_now_ns() + (uint64_t)t->cfg.stats_interval_ms * 1000000ull;

	if (tick_ms < 1)
		tick_ms = 1;
	while (atomic_load_explicit(&t->running, memory_order_acquire)) {
		poll_clients(t, tick_ms);
		telem__client_deadlines(t, mono_now_ns());
		drain_ring(t);
		drain_events(t);
		telem__drain_replies(t);
		if (t->cfg.stats_interval_ms && mono_now_ns() >= next_stats) {
			send_stats(t, 0);
			next_stats += (uint64_t)t->cfg.stats_interval_ms * 1000000ull;
			if (next_stats < mono_now_ns())
				next_stats = mono_now_ns() + (uint64_t)t->cfg.stats_interval_ms * 1000000ull;
		}
		flush_all(t);
	}
	/* last drain: the cycle thread has stopped pushing (telem_stop contract) */
	drain_ring(t);
	{
		uint64_t pushed = atomic_load_explicit(&t->pushed, memory_order_acquire);

		if (pushed > t->expect_seq) {	/* dropped records at the very end */
			uint64_t last = atomic_load_explicit(&t->last_cycle, memory_order_relaxed);
			uint64_t lost = pushed - t->expect_seq;
			uint64_t now = mono_now_ns();

			telem__broadcast_ring_gap(t, now,
						  t->have_prev ? t->prev_cycle + 1u : last + 1u - lost,
						  last, lost);
			t->expect_seq = pushed;
		}
	}
	drain_events(t);
	{
		uint64_t end = mono_now_ns() + (uint64_t)t->cfg.linger_ms * 1000000ull;

		/* flush first so that the final STATS finds room, then once more */
		for (int pass = 0; pass < 2; pass++) {
			if (pass)
				send_stats(t, STATS_F_FINAL);
			flush_all(t);
			while (pending(t) && mono_now_ns() < end) {
				poll_clients(t, 5);
				flush_all(t);
			}
		}
	}
	for (unsigned i = 0; i < TELEM_MAX_CLIENTS; i++) {
		struct telem_client *c = &t->clients[i];

		if (c->fd >= 0) {
			shutdown(c->fd, SHUT_WR);
			telem__client_read(t, c);	/* drop anything the client sent */
			telem__client_close(t, c);
		}
	}
	return NULL;
}

int telem_start(struct telem *t)
{
	int rc;

	if (t->started)
		return -EALREADY;
	atomic_store_explicit(&t->running, 1, memory_order_release);
	rc = pthread_create(&t->thread, NULL, drain_main, t);
	if (rc) {
		atomic_store_explicit(&t->running, 0, memory_order_release);
		return -rc;
	}
	t->started = 1;
	return 0;
}

void telem_stop(struct telem *t)
{
	if (!t->started)
		return;
	atomic_store_explicit(&t->running, 0, memory_order_release);
	if (write(t->wake_fd[1], "x", 1) < 0) {
		/* the drain thread also wakes up every drain interval */
	}
	pthread_join(t->thread, NULL);
	t->started = 0;
}
