// SPDX-License-Identifier: MIT
/*
 * telem_client.c - the drain thread's clients: accepting a connection
 * into a slot, the AUTH frame, reading what a client sends, its send
 * buffer (client_put, the client-overflow GAP, broadcast), its deadlines,
 * and flushing it to the socket.
 */
#define _GNU_SOURCE
#include "telem_internal.h"

#include <errno.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <stdlib.h>
#include <sys/socket.h>
#include <unistd.h>

/* ---- drain thread: clients ------------------------------------------------------ */
void telem__client_close(struct telem *t, struct telem_client *c)
{
	if (c->fd < 0)
		return;
	close(c->fd);
	c->fd = -1;
	free(c->buf);
	c->buf = NULL;
	c->off = c->len = 0;
	if (c->authed)
		atomic_fetch_sub_explicit(&t->clients_now, 1u, memory_order_relaxed);
	c->authed = 0;
}

/* Close a client for a reason the server has (counted). */
static void client_drop(struct telem *t, struct telem_client *c, _Atomic uint64_t *reason)
{
	if (c->fd < 0)
		return;
	atomic_fetch_add_explicit(reason, 1u, memory_order_relaxed);
	telem__client_close(t, c);
}

static size_t client_room(struct telem *t, struct telem_client *c, size_t need)
{
	if (t->cfg.client_buffer - c->len < need && c->off) {
		memmove(c->buf, c->buf + c->off, c->len - c->off);
		c->len -= c->off;
		c->off = 0;
	}
	return t->cfg.client_buffer - c->len;
}

static void client_append(struct telem_client *c, const void *m, size_t n)
{
	memcpy(c->buf + c->len, m, n);
	c->len += n;
}

/* Bytes kept free for non-cycle messages (PARAM, LOG, GAP, STATS) so that a
 * slow client loses cycle records first. */
#define EVENT_RESERVE (16u * 1024u)

/* Queue one message for a client. For CYCLE messages (cycle != NULL) a full
 * buffer loses the record and opens a client-overflow gap, which is sent
 * before the next message that fits. */
void telem__client_put(struct telem *t, struct telem_client *c, const unsigned char *m, size_t n,
		       const uint64_t *cycle, uint64_t t_ns)
{
	size_t need = n + (c->lost ? FRAME_HDR + GAP_LEN : 0u) + (cycle ? EVENT_RESERVE : 0u);

	if (!live(c))
		return;
	if (client_room(t, c, need) < need) {
		if (cycle) {
			if (!c->lost)
				c->lost_from = *cycle;
			c->lost_to = *cycle;
			c->lost++;
			c->lost_total++;
			atomic_fetch_add_explicit(&t->client_lost, 1u, memory_order_relaxed);
		} else {
			c->events_lost++;
		}
		return;
	}
	if (c->lost) {
		unsigned char g[FRAME_HDR + GAP_LEN];

		telem__enc_gap(g, t_ns, c->lost_from, c->lost_to, c->lost, TELEM_GAP_CLIENT_OVERFLOW);
		client_append(c, g, sizeof(g));
		c->lost = 0;
	}
	client_append(c, m, n);
}

/* A ring-overflow gap (cycles from..to dropped by the producer). A client
 * whose buffer cannot take it gets the range folded into its own overflow
 * gap, so that every missing cycle is still covered by exactly one GAP. */
void telem__broadcast_ring_gap(struct telem *t, uint64_t t_ns, uint64_t from, uint64_t to,
			       uint64_t count)
{
	unsigned char g[FRAME_HDR + GAP_LEN];

	telem__enc_gap(g, t_ns, from, to, count, TELEM_GAP_RING_OVERFLOW);
	for (unsigned i = 0; i < TELEM_MAX_CLIENTS; i++) {
		struct telem_client *c = &t->clients[i];
		size_t need = sizeof(g) + (c->lost ? FRAME_HDR + GAP_LEN : 0u);

		if (!live(c))
			continue;
		if (!c->lost && client_room(t, c, need) >= need) {
			client_append(c, g, sizeof(g));
		} else if (c->lost && client_room(t, c, need) >= need) {
			telem__client_put(t, c, g, sizeof(g), NULL, t_ns);
		} else {
			if (!c->lost)
				c->lost_from = from;
			c->lost_to = to;
			c->lost += count;
		}
	}
}

void telem__broadcast(struct telem *t, const unsigned char *m, size_t n, const uint64_t *cycle,
		      uint64_t t_ns)
{
	for (unsigned i = 0; i < TELEM_MAX_CLIENTS; i++)
		if (live(&t->clients[i]))
			telem__client_put(t, &t->clients[i], m, n, cycle, t_ns);
}

/* A slot for a new connection: a free one (within max_clients), else the
 * one of the oldest connection that has not authenticated yet (it is closed:
 * idle or slow connections cannot lock the recorder out), else none. */
static struct telem_client *client_slot(struct telem *t)
{
	struct telem_client *pend = NULL;
	unsigned used = 0;

	for (unsigned i = 0; i < TELEM_MAX_CLIENTS; i++) {
		struct telem_client *c = &t->clients[i];

		if (c->fd < 0)
			continue;
		used++;
		if (!c->authed && (!pend || c->t_conn < pend->t_conn))
			pend = c;
	}
	if (used < t->cfg.max_clients)
		for (unsigned i = 0; i < TELEM_MAX_CLIENTS; i++)
			if (t->clients[i].fd < 0)
				return &t->clients[i];
	if (pend) {
		client_drop(t, pend, &t->drop_evicted);
		return pend;
	}
	return NULL;
}

void telem__accept_clients(struct telem *t)
{
	for (;;) {
		int fd = accept4(t->listen_fd, NULL, NULL, SOCK_NONBLOCK | SOCK_CLOEXEC);
		struct telem_client *c;
		int one = 1;

		if (fd < 0)
			return;
		c = client_slot(t);
		if (!c) {
			atomic_fetch_add_explicit(&t->drop_refused, 1u, memory_order_relaxed);
			close(fd);	/* every slot streams to an authenticated client */
			continue;
		}
		if (!(c->buf = malloc(t->cfg.client_buffer))) {
			close(fd);
			continue;
		}
		setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof(one));
		c->fd = fd;
		c->off = c->len = 0;
		c->lost = c->lost_total = c->events_lost = 0;
		c->authed = 0;
		c->in_len = c->in_flight = 0;
		c->t_conn = c->t_progress = mono_now_ns();
		c->conn = atomic_fetch_add_explicit(&t->clients_total, 1u, memory_order_relaxed) + 1u;
	}
}

/* Constant-time comparison of the AUTH payload with the token. */
static int token_ok(const struct telem *t, const unsigned char *p, uint32_t n)
{
	unsigned char d = 0;

	if (!t->cfg.token_len)
		return 1;
	if (n != t->cfg.token_len)
		return 0;
	for (uint32_t i = 0; i < n; i++)
		d |= (unsigned char)(p[i] ^ t->token[i]);
	return d == 0;
}

/* The AUTH frame so far in c->in: 1 complete and accepted, 0 incomplete,
 * -1 refused. */
static int auth_check(struct telem *t, struct telem_client *c)
{
	uint16_t type, flags;
	uint32_t len;

	if (c->in_len < FRAME_HDR)
		return 0;
	in_hdr(c, &type, &flags, &len);
	if (type != TELEM_MSG_AUTH || flags || len > TELEM_TOKEN_MAX)
		return -1;
	if (c->in_len < FRAME_HDR + len)
		return 0;
	return token_ok(t, c->in + FRAME_HDR, len) ? 1 : -1;
}

static void client_authed(struct telem *t, struct telem_client *c)
{
	unsigned char hello[FRAME_HDR + HELLO_LEN];

	c->authed = 1;
	c->in_len = 0;
	c->t_progress = mono_now_ns();
	atomic_fetch_add_explicit(&t->clients_now, 1u, memory_order_relaxed);
	client_append(c, hello, telem__enc_hello(t, hello));
}

/* At most CLIENT_READ_MAX bytes per call, one frame at a time and exactly
 * its bytes: the AUTH frame, then REQUEST frames; anything else closes the
 * client. */
void telem__client_read(struct telem *t, struct telem_client *c)
{
	size_t budget = CLIENT_READ_MAX;

	while (c->fd >= 0 && budget) {
		uint32_t len = 0;
		unsigned char *dst = c->in + c->in_len;
		size_t want;
		ssize_t n;

		/* the header's length was checked when the header completed */
		if (c->in_len >= FRAME_HDR)
			memcpy(&len, c->in + 4, 4);
		want = (c->in_len < FRAME_HDR ? FRAME_HDR : FRAME_HDR + len) - c->in_len;
		n = recv(c->fd, dst, want, MSG_DONTWAIT);
		if (n < 0 && errno == EINTR)
			continue;
		if (n == 0 || (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK)) {
			telem__client_close(t, c);
			return;
		}
		if (n < 0)
			return;		/* nothing more for now */
		budget -= (size_t)n;
		c->in_len += (uint32_t)n;
		if (!c->authed) {
			int ok = auth_check(t, c);

			if (ok < 0)
				client_drop(t, c, &t->drop_auth_failed);
			else if (ok > 0)
				client_authed(t, c);
			continue;
		}
		switch (telem__request_check(c)) {
		case -1:
			client_drop(t, c, &t->drop_protocol);
			break;
		case 1:
			telem__request_take(t, c);
			c->in_len = 0;
			break;
		default:
			break;
		}
	}
}

/* Deadlines: no AUTH in time, or a socket that took no byte for too long. */
void telem__client_deadlines(struct telem *t, uint64_t now)
{
	uint64_t auth_ns = (uint64_t)t->cfg.auth_timeout_ms * 1000000ull;
	uint64_t stall_ns = (uint64_t)t->cfg.stall_timeout_ms * 1000000ull;

	for (unsigned i = 0; i < TELEM_MAX_CLIENTS; i++) {
		struct telem_client *c = &t->clients[i];

		if (c->fd < 0)
			continue;
		if (!c->authed && now - c->t_conn > auth_ns)
			client_drop(t, c, &t->drop_auth_timeout);
		else if (c->authed && c->off < c->len && now - c->t_progress > stall_ns)
			client_drop(t, c, &t->drop_stalled);
	}
}

void telem__client_flush(struct telem *t, struct telem_client *c)
{
	while (live(c) && c->off < c->len) {
		ssize_t n = send(c->fd, c->buf + c->off, c->len - c->off, MSG_DONTWAIT | MSG_NOSIGNAL);

		if (n > 0) {
			c->off += (size_t)n;
			c->t_progress = mono_now_ns();
			atomic_fetch_add_explicit(&t->bytes_sent, (uint64_t)n, memory_order_relaxed);
		} else if (n < 0 && errno == EINTR) {
			continue;
		} else if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) {
			return;
		} else {
			telem__client_close(t, c);
		}
	}
	if (live(c) && c->off == c->len) {
		c->off = c->len = 0;
		c->t_progress = mono_now_ns();
	}
}
