// SPDX-License-Identifier: MIT
/*
 * telem.c - servoamp telemetry transport: SPSC ring + TCP streaming server.
 * Wire format: docs/telemetry.md. API: telem.h. This file: the
 * configuration, telem_init/telem_destroy and the listening socket; the
 * rest is listed in telem_internal.h.
 */
#define _GNU_SOURCE
#include "telem_internal.h"

#include <errno.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <stdio.h>
#include <stdlib.h>
#include <sys/mman.h>
#include <sys/random.h>
#include <sys/socket.h>
#include <unistd.h>

#if !defined(__BYTE_ORDER__) || __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "the telemetry wire format is little-endian; add byte swapping for this target"
#endif
_Static_assert(ATOMIC_LLONG_LOCK_FREE == 2, "64-bit atomics must be lock-free (RT safety)");
_Static_assert(ATOMIC_INT_LOCK_FREE == 2, "32-bit atomics must be lock-free");

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
		v = telem__realtime_ns() ^ ((uint64_t)getpid() << 32);
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

void telem_destroy(struct telem *t)
{
	telem_stop(t);
	if (t->clients)
		for (unsigned i = 0; i < TELEM_MAX_CLIENTS; i++)
			telem__client_close(t, &t->clients[i]);
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
