/* SPDX-License-Identifier: MIT */
/*
 * telem_internal.h - what the files of the telemetry transport share: the
 * wire sizes of docs/telemetry.md, the little-endian encoders, the internal
 * records (cycle slot, event, reply, client) and the functions one file
 * calls in another (telem__ prefix). Not an API: telem.h is the one API.
 *
 *   telem.c          configuration, init/destroy, the listening socket
 *   telem_push.c     producers: telem_push_*, telem_get_stats
 *   telem_wire.c     message encoding: enc_* (CYCLE, GAP, HELLO, REPLY)
 *   telem_client.c   drain thread, clients: accept, AUTH, read, buffer, send
 *   telem_request.c  requests and replies
 *   telem_drain.c    drain thread: ring, events, STATS, poll, start/stop
 *
 * Each including file defines _GNU_SOURCE before its first header.
 */
#ifndef SERVOAMP_TELEM_INTERNAL_H
#define SERVOAMP_TELEM_INTERNAL_H

#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "telem.h"
#include "servoamp/mono_clock.h"

/* ---- wire sizes (docs/telemetry.md) ---- */
#define FRAME_HDR 8u
#define HELLO_LEN 80u
#define CYCLE_HDR_LEN 52u
#define AXIS_LEN 36u
#define STATS_HDR_LEN 104u
#define COUNTER_LEN 32u
#define PARAM_LEN 80u
#define LOG_HDR_LEN 40u
#define GAP_LEN 40u
#define QUEUES_HDR_LEN 16u
#define QUEUE_LEN 24u
#define EVENT_MAX (FRAME_HDR + LOG_HDR_LEN + TELEM_LOG_MAX)
#define STATS_MAX (FRAME_HDR + STATS_HDR_LEN + COUNTER_LEN * TELEM_MAX_COUNTERS)

_Static_assert(FRAME_HDR + QUEUES_HDR_LEN + QUEUE_LEN * TELEM_MAX_QUEUES <= EVENT_MAX, "queues");
_Static_assert(FRAME_HDR + PARAM_LEN <= EVENT_MAX, "param");

#define STATS_F_FINAL 1u

struct telem_slot {
	uint64_t seq;			/* telem_push_cycle call number, from 0 */
	struct telem_cycle c;
};

struct telem_event {
	uint32_t len;
	unsigned char data[EVENT_MAX];
};

/* A reply waiting for the drain thread (telem_reply). */
#define REPLY_HDR 12u
#define REQ_QUEUE (TELEM_MAX_CLIENTS * TELEM_REQ_PER_CLIENT)
struct telem_reply {
	uint32_t slot;
	uint64_t conn;
	uint32_t len;
	unsigned char data[FRAME_HDR + REPLY_HDR + TELEM_REPLY_MAX];
};

struct telem_client {
	int fd;
	unsigned char *buf;
	size_t off, len;		/* pending bytes: buf[off, len) */
	uint64_t lost, lost_from, lost_to;	/* cycles not sent (buffer full) */
	uint64_t lost_total;		/* cycles this client lost, in total */
	uint64_t events_lost;
	int authed;			/* AUTH accepted: the client gets the stream */
	uint64_t t_conn;		/* accepted at (CLOCK_MONOTONIC ns) */
	uint64_t t_progress;		/* last time its socket took bytes, or its buffer was empty */
	uint32_t in_len;		/* bytes of the frame (AUTH, then REQUEST) received so far */
	uint64_t conn;			/* connection serial (replies find their client) */
	uint32_t in_flight;		/* its requests not answered yet */
	unsigned char in[8 + 4 + TELEM_REQ_MAX];
};

/* What one client may send: one AUTH frame, then REQUEST frames only (any
 * other frame closes it). client_read takes at most CLIENT_READ_MAX bytes
 * per pass (a flooding client cannot keep the drain thread in recv). */
#define CLIENT_READ_MAX 4096u

/* ---- little-endian encoding ---- */
static inline unsigned char *put16(unsigned char *p, uint16_t v) { memcpy(p, &v, 2); return p + 2; }
static inline unsigned char *put32(unsigned char *p, uint32_t v) { memcpy(p, &v, 4); return p + 4; }
static inline unsigned char *puti32(unsigned char *p, int32_t v) { memcpy(p, &v, 4); return p + 4; }
static inline unsigned char *put64(unsigned char *p, uint64_t v) { memcpy(p, &v, 8); return p + 8; }
static inline unsigned char *putf64(unsigned char *p, double v) { memcpy(p, &v, 8); return p + 8; }

static inline unsigned char *putstr(unsigned char *p, const char *s, size_t field)
{
	size_t n = s ? strnlen(s, field - 1u) : 0u;

	memset(p, 0, field);
	if (n)
		memcpy(p, s, n);
	return p + field;
}

static inline unsigned char *frame(unsigned char *p, uint16_t type, uint32_t len)
{
	p = put16(p, type);
	p = put16(p, 0);
	return put32(p, len);
}

/* A client that gets the stream: connected and authenticated. */
static inline int live(const struct telem_client *c)
{
	return c->fd >= 0 && c->authed;
}

/* The header of the frame being received in c->in (at least FRAME_HDR bytes). */
static inline void in_hdr(const struct telem_client *c, uint16_t *type, uint16_t *flags,
			  uint32_t *len)
{
	memcpy(type, c->in, 2);
	memcpy(flags, c->in + 2, 2);
	memcpy(len, c->in + 4, 4);
}

/* ---- telem_wire.c: messages; each returns its end, or its length ---- */
uint64_t telem__realtime_ns(void);
unsigned char *telem__enc_gap(unsigned char *p, uint64_t t_ns, uint64_t from, uint64_t to,
			      uint64_t count, uint32_t reason);
size_t telem__enc_hello(struct telem *t, unsigned char *b);
size_t telem__enc_reply(unsigned char *b, uint32_t id, int32_t status, const char *text, size_t len);
size_t telem__enc_cycle(struct telem *t, unsigned char *b, const struct telem_cycle *c);

/* ---- telem_client.c: the drain thread's clients ---- */
void telem__client_close(struct telem *t, struct telem_client *c);
/* Queue one message for a client (a CYCLE message: cycle != NULL). */
void telem__client_put(struct telem *t, struct telem_client *c, const unsigned char *m, size_t n,
		       const uint64_t *cycle, uint64_t t_ns);
void telem__broadcast(struct telem *t, const unsigned char *m, size_t n, const uint64_t *cycle,
		      uint64_t t_ns);
void telem__broadcast_ring_gap(struct telem *t, uint64_t t_ns, uint64_t from, uint64_t to,
			       uint64_t count);
void telem__accept_clients(struct telem *t);
void telem__client_read(struct telem *t, struct telem_client *c);
void telem__client_deadlines(struct telem *t, uint64_t now);
void telem__client_flush(struct telem *t, struct telem_client *c);

/* ---- telem_request.c: REQUEST frames in, REPLY frames out ---- */
int telem__request_check(const struct telem_client *c);
void telem__request_take(struct telem *t, struct telem_client *c);
void telem__drain_replies(struct telem *t);

#endif /* SERVOAMP_TELEM_INTERNAL_H */
