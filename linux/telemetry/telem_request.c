// SPDX-License-Identifier: MIT
/*
 * telem_request.c - requests and replies: a client's complete REQUEST
 * frame queued for the application (or answered at once), telem_pop_request
 * and telem_reply for the application, and the replies the drain thread
 * sends to the clients that asked.
 */
#define _GNU_SOURCE
#include "telem_internal.h"

#include <pthread.h>
#include <unistd.h>

/* The REQUEST frame so far in c->in: 1 complete, 0 incomplete, -1 not a
 * REQUEST (type, flags, or a length outside 4..4 + TELEM_REQ_MAX). */
int telem__request_check(const struct telem_client *c)
{
	uint16_t type, flags;
	uint32_t len;

	if (c->in_len < FRAME_HDR)
		return 0;
	in_hdr(c, &type, &flags, &len);
	if (type != TELEM_MSG_REQUEST || flags || len < 4u || len > 4u + TELEM_REQ_MAX)
		return -1;
	return c->in_len >= FRAME_HDR + len;
}

/* A complete REQUEST in c->in: queued for the application, or answered at
 * once (busy, or no request service). */
void telem__request_take(struct telem *t, struct telem_client *c)
{
	uint32_t id, len;
	struct telem_request *r;

	memcpy(&len, c->in + 4, 4);
	memcpy(&id, c->in + FRAME_HDR, 4);
	len -= 4u;
	pthread_mutex_lock(&t->ev_lock);
	if (t->cfg.requests && c->in_flight < TELEM_REQ_PER_CLIENT && t->req_head - t->req_tail < REQ_QUEUE) {
		r = &t->req[t->req_head % REQ_QUEUE];
		r->slot = (uint32_t)(c - t->clients);
		r->conn = c->conn;
		r->id = id;
		r->len = len;
		memcpy(r->text, c->in + FRAME_HDR + 4u, len);
		r->text[len] = 0;
		t->req_head++;
		c->in_flight++;
		pthread_mutex_unlock(&t->ev_lock);
	} else {
		unsigned char b[FRAME_HDR + REPLY_HDR + 64];
		const char *why = t->cfg.requests ? "busy: too many requests in flight" : "no requests served";
		size_t n;

		pthread_mutex_unlock(&t->ev_lock);
		n = telem__enc_reply(b, id, t->cfg.requests ? TELEM_REPLY_BUSY : TELEM_REPLY_UNSERVED,
				     why, strlen(why));
		telem__client_put(t, c, b, n, NULL, mono_now_ns());
	}
}

/* Replies (telem_reply) to the clients that asked, if still connected. */
void telem__drain_replies(struct telem *t)
{
	pthread_mutex_lock(&t->ev_lock);
	while (t->rep_tail != t->rep_head) {
		struct telem_reply *r = &t->rep[t->rep_tail % REQ_QUEUE];
		struct telem_client *c = &t->clients[r->slot];

		if (c->fd >= 0 && c->conn == r->conn) {
			if (c->in_flight)
				c->in_flight--;
			telem__client_put(t, c, r->data, r->len, NULL, mono_now_ns());
		}
		t->rep_tail++;
	}
	pthread_mutex_unlock(&t->ev_lock);
}

int telem_pop_request(struct telem *t, struct telem_request *r)
{
	int got = 0;

	pthread_mutex_lock(&t->ev_lock);
	if (t->req_tail != t->req_head) {
		*r = t->req[t->req_tail % REQ_QUEUE];
		t->req_tail++;
		got = 1;
	}
	pthread_mutex_unlock(&t->ev_lock);
	return got;
}

int telem_reply(struct telem *t, const struct telem_request *r, int32_t status, const char *text, size_t len)
{
	struct telem_reply *e;
	char one = 1;

	if (r->slot >= TELEM_MAX_CLIENTS)
		return -1;
	pthread_mutex_lock(&t->ev_lock);
	if (t->rep_head - t->rep_tail >= REQ_QUEUE) {
		pthread_mutex_unlock(&t->ev_lock);
		return -1;
	}
	e = &t->rep[t->rep_head % REQ_QUEUE];
	e->slot = r->slot;
	e->conn = r->conn;
	e->len = (uint32_t)telem__enc_reply(e->data, r->id, status, text ? text : "", text ? len : 0u);
	t->rep_head++;
	pthread_mutex_unlock(&t->ev_lock);
	if (write(t->wake_fd[1], &one, 1) < 0) {
		/* the pipe is full: the drain thread is awake anyway */
	}
	return 0;
}
