// SPDX-License-Identifier: MIT
/*
 * telem.c - servoamp telemetry transport: SPSC ring + TCP streaming server.
 * Wire format: docs/telemetry.md. API: telem.h.
 */
#define _GNU_SOURCE
#include "telem.h"
#include "servoamp/mono_clock.h"

#include <errno.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/random.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#if !defined(__BYTE_ORDER__) || __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "the telemetry wire format is little-endian; add byte swapping for this target"
#endif
_Static_assert(ATOMIC_LLONG_LOCK_FREE == 2, "64-bit atomics must be lock-free (RT safety)");
_Static_assert(ATOMIC_INT_LOCK_FREE == 2, "32-bit atomics must be lock-free");

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
static unsigned char *put16(unsigned char *p, uint16_t v) { memcpy(p, &v, 2); return p + 2; }
static unsigned char *put32(unsigned char *p, uint32_t v) { memcpy(p, &v, 4); return p + 4; }
static unsigned char *puti32(unsigned char *p, int32_t v) { memcpy(p, &v, 4); return p + 4; }
static unsigned char *put64(unsigned char *p, uint64_t v) { memcpy(p, &v, 8); return p + 8; }
static unsigned char *putf64(unsigned char *p, double v) { memcpy(p, &v, 8); return p + 8; }

static unsigned char *putstr(unsigned char *p, const char *s, size_t field)
{
	size_t n = s ? strnlen(s, field - 1u) : 0u;

	memset(p, 0, field);
	if (n)
		memcpy(p, s, n);
	return p + field;
}

static unsigned char *frame(unsigned char *p, uint16_t type, uint32_t len)
{
	p = put16(p, type);
	p = put16(p, 0);
	return put32(p, len);
}

static uint64_t realtime_ns(void)
{
	struct timespec ts;

	clock_gettime(CLOCK_REALTIME, &ts);
	return (uint64_t)ts.tv_sec * 1000000000ull + (uint64_t)ts.tv_nsec;
}

/* ---- configuration ----------------------------------------------------------- */
void telem_cfg_defaults(struct telem_cfg *cfg)
{
	memset(cfg, 0, sizeof(*cfg));
	cfg->listen_addr = "127.0.0.1";
	cfg->port = TELEM_DEFAULT_PORT;
	cfg->controller_id = "servoamp";
	cfg->n_axes = AMP_MAX_AXES;
	cfg->cycle_period_ns = 1000000u;
	cfg->clock_hz = 1000000000u;
	cfg->ring_capacity = 4096u;
	cfg->event_capacity = 256u;
	cfg->client_buffer = 1u << 20;
	cfg->max_clients = 4u;
	cfg->drain_interval_us = 2000u;
	cfg->stats_interval_ms = 1000u;
	cfg->linger_ms = 1000u;
	cfg->auth_timeout_ms = 2000u;
	cfg->stall_timeout_ms = 10000u;
}

/* The session id needs uniqueness, not secrecy: never wait for the kernel's
 * entropy. (Early after boot, a read of /dev/urandom on Linux >= 5.18 first
 * runs the jitter entropy generator: 2.6 s under QEMU TCG, which delayed
 * servod's start on the emulated board.) */
static uint64_t random_id(void)
{
	uint64_t v = 0;
#ifdef GRND_INSECURE
	if (getrandom(&v, sizeof(v), GRND_INSECURE) != (ssize_t)sizeof(v))
#endif
		if (getrandom(&v, sizeof(v), GRND_NONBLOCK) != (ssize_t)sizeof(v))
			v = 0;
	if (!v)
		v = realtime_ns() ^ ((uint64_t)getpid() << 32);
	return v ? v : 1u;
}

static int listen_on(struct telem *t)
{
	struct addrinfo hints, *ai = NULL;
	char port[8];
	int fd, one = 1, rc;

	memset(&hints, 0, sizeof(hints));
	hints.ai_family = AF_UNSPEC;
	hints.ai_socktype = SOCK_STREAM;
	hints.ai_flags = AI_PASSIVE | AI_NUMERICHOST | AI_NUMERICSERV;
	snprintf(port, sizeof(port), "%u", (unsigned)t->cfg.port);
	rc = getaddrinfo(t->cfg.listen_addr, port, &hints, &ai);
	if (rc || !ai)
		return -EINVAL;
	fd = socket(ai->ai_family, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
	if (fd < 0) {
		rc = -errno;
		freeaddrinfo(ai);
		return rc;
	}
	setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof(one));
	if (bind(fd, ai->ai_addr, ai->ai_addrlen) || listen(fd, 8)) {
		rc = -errno;
		close(fd);
		freeaddrinfo(ai);
		return rc;
	}
	freeaddrinfo(ai);
	{
		struct sockaddr_storage ss;
		socklen_t sl = sizeof(ss);

		if (getsockname(fd, (struct sockaddr *)&ss, &sl) == 0) {
			if (ss.ss_family == AF_INET)
				t->port = ntohs(((struct sockaddr_in *)&ss)->sin_port);
			else if (ss.ss_family == AF_INET6)
				t->port = ntohs(((struct sockaddr_in6 *)&ss)->sin6_port);
		}
	}
	t->listen_fd = fd;
	return 0;
}

int telem_init(struct telem *t, const struct telem_cfg *cfg)
{
	int rc, ring_rc;

	memset(t, 0, sizeof(*t));
	t->listen_fd = -1;
	t->wake_fd[0] = t->wake_fd[1] = -1;
	if (!cfg || !cfg->listen_addr || cfg->n_axes < 1u || cfg->n_axes > AMP_MAX_AXES ||
	    cfg->event_capacity < 1u || cfg->max_clients < 1u || cfg->max_clients > TELEM_MAX_CLIENTS ||
	    cfg->client_buffer < 64u * 1024u || cfg->drain_interval_us < 100u ||
	    cfg->ring_capacity < 2u || (cfg->ring_capacity & (cfg->ring_capacity - 1u)) ||
	    cfg->token_len > TELEM_TOKEN_MAX || (cfg->token_len && !cfg->token) ||
	    cfg->auth_timeout_ms < 1u || cfg->stall_timeout_ms < 1u)
		return -EINVAL;
	t->cfg = *cfg;
	if (cfg->token_len)
		memcpy(t->token, cfg->token, cfg->token_len);
	t->cfg.token = cfg->token_len ? t->token : NULL;
	snprintf(t->controller_id, sizeof(t->controller_id), "%s",
		 cfg->controller_id ? cfg->controller_id : "");
	t->cfg.controller_id = t->controller_id;
	t->session_id = random_id();

	ring_rc = ring_init(&t->ring, sizeof(struct telem_slot), cfg->ring_capacity);
	t->ev = calloc(cfg->event_capacity, sizeof(struct telem_event));
	t->clients = calloc(TELEM_MAX_CLIENTS, sizeof(struct telem_client));
	t->req = calloc(REQ_QUEUE, sizeof(struct telem_request));
	t->rep = calloc(REQ_QUEUE, sizeof(struct telem_reply));
	t->scratch_cap = FRAME_HDR + CYCLE_HDR_LEN + AXIS_LEN * AMP_MAX_AXES + EVENT_MAX;
	t->scratch = malloc(t->scratch_cap);
	if (ring_rc || !t->ev || !t->clients || !t->scratch || !t->req || !t->rep) {
		rc = -ENOMEM;
		goto fail;
	}
	if (cfg->mlock)	/* best effort; servod also mlockall()s */
		(void)mlock(t->ring.buf, RING_BUF_BYTES(sizeof(struct telem_slot), cfg->ring_capacity));
	for (unsigned i = 0; i < TELEM_MAX_CLIENTS; i++)
		t->clients[i].fd = -1;
	t->ev_cap = cfg->event_capacity;
	if (pthread_mutex_init(&t->ev_lock, NULL)) {
		rc = -ENOMEM;
		goto fail;
	}
	if (pipe2(t->wake_fd, O_CLOEXEC | O_NONBLOCK)) {
		rc = -errno;
		pthread_mutex_destroy(&t->ev_lock);
		goto fail;
	}
	t->port = cfg->port;
	rc = listen_on(t);
	if (rc) {
		pthread_mutex_destroy(&t->ev_lock);
		close(t->wake_fd[0]);
		close(t->wake_fd[1]);
		goto fail;
	}
	return 0;
fail:
	ring_free(&t->ring);
	free(t->ev);
	free(t->clients);
	free(t->scratch);
	free(t->req);
	free(t->rep);
	t->req = NULL;
	t->rep = NULL;
	t->ev = NULL;
	t->clients = NULL;
	t->scratch = NULL;
	t->wake_fd[0] = t->wake_fd[1] = -1;
	return rc;
}

uint16_t telem_port(const struct telem *t)
{
	return t->port;
}

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

static unsigned char *enc_gap(unsigned char *p, uint64_t t_ns, uint64_t from, uint64_t to,
			      uint64_t count, uint32_t reason)
{
	p = frame(p, TELEM_MSG_GAP, GAP_LEN);
	p = put64(p, t_ns);
	p = put64(p, from);
	p = put64(p, to);
	p = put64(p, count);
	p = put32(p, reason);
	return put32(p, 0);
}

int telem_push_gap(struct telem *t, uint64_t t_ns, uint64_t from_cycle, uint64_t to_cycle,
		   uint64_t count, uint32_t reason)
{
	unsigned char b[FRAME_HDR + GAP_LEN];

	enc_gap(b, now_or(t_ns), from_cycle, to_cycle, count, reason);
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

/* ---- drain thread: clients ------------------------------------------------------ */
static void client_close(struct telem *t, struct telem_client *c)
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
	client_close(t, c);
}

/* A client that gets the stream: connected and authenticated. */
static int live(const struct telem_client *c)
{
	return c->fd >= 0 && c->authed;
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
static void client_put(struct telem *t, struct telem_client *c, const unsigned char *m, size_t n,
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

		enc_gap(g, t_ns, c->lost_from, c->lost_to, c->lost, TELEM_GAP_CLIENT_OVERFLOW);
		client_append(c, g, sizeof(g));
		c->lost = 0;
	}
	client_append(c, m, n);
}

/* A ring-overflow gap (cycles from..to dropped by the producer). A client
 * whose buffer cannot take it gets the range folded into its own overflow
 * gap, so that every missing cycle is still covered by exactly one GAP. */
static void broadcast_ring_gap(struct telem *t, uint64_t t_ns, uint64_t from, uint64_t to,
			       uint64_t count)
{
	unsigned char g[FRAME_HDR + GAP_LEN];

	enc_gap(g, t_ns, from, to, count, TELEM_GAP_RING_OVERFLOW);
	for (unsigned i = 0; i < TELEM_MAX_CLIENTS; i++) {
		struct telem_client *c = &t->clients[i];
		size_t need = sizeof(g) + (c->lost ? FRAME_HDR + GAP_LEN : 0u);

		if (!live(c))
			continue;
		if (!c->lost && client_room(t, c, need) >= need) {
			client_append(c, g, sizeof(g));
		} else if (c->lost && client_room(t, c, need) >= need) {
			client_put(t, c, g, sizeof(g), NULL, t_ns);
		} else {
			if (!c->lost)
				c->lost_from = from;
			c->lost_to = to;
			c->lost += count;
		}
	}
}

static void broadcast(struct telem *t, const unsigned char *m, size_t n, const uint64_t *cycle,
		      uint64_t t_ns)
{
	for (unsigned i = 0; i < TELEM_MAX_CLIENTS; i++)
		if (live(&t->clients[i]))
			client_put(t, &t->clients[i], m, n, cycle, t_ns);
}

static size_t enc_hello(struct telem *t, unsigned char *b)
{
	unsigned char *p = frame(b, TELEM_MSG_HELLO, HELLO_LEN);

	p = put32(p, TELEM_MAGIC);
	p = put16(p, TELEM_WIRE_VERSION);
	p = put16(p, 0);
	p = put64(p, t->session_id);
	p = put64(p, mono_now_ns());
	p = put64(p, realtime_ns());
	p = put32(p, t->cfg.n_axes);
	p = put32(p, t->cfg.cycle_period_ns);
	p = put32(p, t->cfg.clock_hz);
	p = put32(p, t->cfg.ring_capacity);
	p = putstr(p, t->controller_id, TELEM_ID_LEN);
	return (size_t)(p - b);
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

static void accept_clients(struct telem *t)
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

/* The header of the frame being received in c->in (at least FRAME_HDR bytes). */
static void in_hdr(const struct telem_client *c, uint16_t *type, uint16_t *flags, uint32_t *len)
{
	memcpy(type, c->in, 2);
	memcpy(flags, c->in + 2, 2);
	memcpy(len, c->in + 4, 4);
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
	client_append(c, hello, enc_hello(t, hello));
}

/* The REQUEST frame so far in c->in: 1 complete, 0 incomplete, -1 not a
 * REQUEST (type, flags, or a length outside 4..4 + TELEM_REQ_MAX). */
static int request_check(const struct telem_client *c)
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

static size_t enc_reply(unsigned char *b, uint32_t id, int32_t status, const char *text, size_t len)
{
	unsigned char *p = b;

	if (len > TELEM_REPLY_MAX)
		len = TELEM_REPLY_MAX;
	p = frame(p, TELEM_MSG_REPLY, REPLY_HDR + (uint32_t)len);
	p = put32(p, id);
	p = puti32(p, status);
	p = put32(p, (uint32_t)len);
	memcpy(p, text, len);
	return (size_t)(p - b) + len;
}

/* A complete REQUEST in c->in: queued for the application, or answered at
 * once (busy, or no request service). */
static void request_take(struct telem *t, struct telem_client *c)
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

		pthread_mutex_unlock(&t->ev_lock);
		client_put(t, c, b, enc_reply(b, id, t->cfg.requests ? TELEM_REPLY_BUSY : TELEM_REPLY_UNSERVED,
					      why, strlen(why)), NULL, mono_now_ns());
	}
}

/* At most CLIENT_READ_MAX bytes per call, one frame at a time and exactly
 * its bytes: the AUTH frame, then REQUEST frames; anything else closes the
 * client. */
static void client_read(struct telem *t, struct telem_client *c)
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
			client_close(t, c);
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
		switch (request_check(c)) {
		case -1:
			client_drop(t, c, &t->drop_protocol);
			break;
		case 1:
			request_take(t, c);
			c->in_len = 0;
			break;
		default:
			break;
		}
	}
}

/* Deadlines: no AUTH in time, or a socket that took no byte for too long. */
static void client_deadlines(struct telem *t, uint64_t now)
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

static void client_flush(struct telem *t, struct telem_client *c)
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
			client_close(t, c);
		}
	}
	if (live(c) && c->off == c->len) {
		c->off = c->len = 0;
		c->t_progress = mono_now_ns();
	}
}

/* ---- drain thread: messages -------------------------------------------------------- */
static size_t enc_cycle(struct telem *t, unsigned char *b, const struct telem_cycle *c)
{
	uint32_t n = t->cfg.n_axes;
	unsigned char *p = frame(b, TELEM_MSG_CYCLE, CYCLE_HDR_LEN + AXIS_LEN * n);

	p = put64(p, c->cycle);
	p = put64(p, c->t_ns);
	p = put32(p, c->servo_cycle);
	p = put32(p, c->t_cycle);
	p = put32(p, c->irq_latency);
	p = put32(p, c->wake_latency_ns);
	p = put32(p, c->exchange);
	p = put32(p, c->missed);
	p = put32(p, c->servo_status);
	p = puti32(p, c->result);
	p = put32(p, c->n_axes < n ? c->n_axes : n);	/* axes with data */
	for (uint32_t i = 0; i < n; i++) {
		static const struct amp_cmd_axis zc;
		static const struct amp_fb_axis zf;
		const struct amp_cmd_axis *a = i < c->n_axes ? &c->cmd[i] : &zc;
		const struct amp_fb_axis *f = i < c->n_axes ? &c->fb[i] : &zf;

		p = put32(p, a->control_word);
		p = puti32(p, a->target_pos);
		p = puti32(p, a->vel_ff);
		p = puti32(p, a->torque_offset);
		p = put32(p, f->status_word);
		p = puti32(p, f->actual_pos);
		p = puti32(p, f->actual_vel);
		p = puti32(p, f->current);
		p = puti32(p, f->following_error);
	}
	return (size_t)(p - b);
}

static void drain_ring(struct telem *t)
{
	const struct telem_slot *s;
	uint32_t level = ring_count(&t->ring);

	if (level > atomic_load_explicit(&t->ring_high_water, memory_order_relaxed))
		atomic_store_explicit(&t->ring_high_water, level, memory_order_relaxed);
	while ((s = ring_front(&t->ring)) != NULL) {
		uint64_t seq = s->seq, cyc = s->c.cycle, t_ns = s->c.t_ns;
		size_t n = enc_cycle(t, t->scratch, &s->c);

		ring_release(&t->ring);
		atomic_fetch_add_explicit(&t->drained, 1u, memory_order_relaxed);
		if (seq != t->expect_seq) {
			/* records expect_seq .. seq-1 were dropped by the producer */
			uint64_t lost = seq - t->expect_seq;
			uint64_t from = t->have_prev ? t->prev_cycle + 1u : cyc - lost;

			broadcast_ring_gap(t, t_ns, from, cyc - 1u, lost);
		}
		t->expect_seq = seq + 1u;
		t->prev_cycle = cyc;
		t->have_prev = 1;
		broadcast(t, t->scratch, n, &cyc, t_ns);
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
			broadcast(t, t->scratch, len, NULL, t_ns);
		}
	}
}

/* Replies (telem_reply) to the clients that asked, if still connected. */
static void drain_replies(struct telem *t)
{
	pthread_mutex_lock(&t->ev_lock);
	while (t->rep_tail != t->rep_head) {
		struct telem_reply *r = &t->rep[t->rep_tail % REQ_QUEUE];
		struct telem_client *c = &t->clients[r->slot];

		if (c->fd >= 0 && c->conn == r->conn) {
			if (c->in_flight)
				c->in_flight--;
			client_put(t, c, r->data, r->len, NULL, mono_now_ns());
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
	e->len = (uint32_t)enc_reply(e->data, r->id, status, text ? text : "", text ? len : 0u);
	t->rep_head++;
	pthread_mutex_unlock(&t->ev_lock);
	if (write(t->wake_fd[1], &one, 1) < 0) {
		/* the pipe is full: the drain thread is awake anyway */
	}
	return 0;
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
		client_put(t, c, b, (size_t)(p - b), NULL, now);
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
		accept_clients(t);
	for (unsigned i = 0; i < TELEM_MAX_CLIENTS; i++)
		if (idx[i] >= 0 && (pfd[idx[i]].revents & (POLLIN | POLLHUP | POLLERR)))
			client_read(t, &t->clients[i]);
	return rc;
}

static void flush_all(struct telem *t)
{
	for (unsigned i = 0; i < TELEM_MAX_CLIENTS; i++)
		client_flush(t, &t->clients[i]);
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
		client_deadlines(t, mono_now_ns());
		drain_ring(t);
		drain_events(t);
		drain_replies(t);
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

			broadcast_ring_gap(t, now, t->have_prev ? t->prev_cycle + 1u : last + 1u - lost,
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
			client_read(t, c);	/* drop anything the client sent */
			client_close(t, c);
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

void telem_destroy(struct telem *t)
{
	telem_stop(t);
	if (t->clients)
		for (unsigned i = 0; i < TELEM_MAX_CLIENTS; i++)
			client_close(t, &t->clients[i]);
	if (t->listen_fd >= 0)
		close(t->listen_fd);
	if (t->wake_fd[0] >= 0) {
		close(t->wake_fd[0]);
		close(t->wake_fd[1]);
		pthread_mutex_destroy(&t->ev_lock);
	}
	ring_free(&t->ring);
	free(t->ev);
	free(t->clients);
	free(t->scratch);
	free(t->req);
	free(t->rep);
	memset(t, 0, sizeof(*t));
	t->listen_fd = -1;
	t->wake_fd[0] = t->wake_fd[1] = -1;
}
