// SPDX-License-Identifier: MIT
/*
 * fuzz_telem_client - what a telemetry client sends, against the server's
 * own telem__client_read() and AUTH handling (linux/telemetry/telem_client.c,
 * linked with the transport's other files; struct telem_client and the wire
 * sizes from telem_internal.h; nothing in them is changed for the harness).
 *
 * Input: one flags byte (bit 0: the server has a token, bit 1: the client
 * closes its end at the end, bit 2: the client then floods 5000 more bytes),
 * then chunks [n][n bytes]: each chunk is written to the client's end of a
 * socketpair and the server reads it with telem__client_read() (at most
 * CLIENT_READ_MAX bytes a call, asserted, called until the socket is
 * empty or the client is gone, a bounded number of times: nothing may
 * loop forever on one client).
 *
 * The oracle is the protocol of docs/telemetry.md computed from the bytes
 * sent: the client is authenticated exactly when its first frame is a
 * whole AUTH frame (type 8, flags 0, length <= 64) carrying the token (any
 * payload without a token); a wrong or malformed AUTH closes it
 * (auth_failed +1); after the AUTH only REQUEST frames (type 9, flags 0,
 * length 4..4 + TELEM_REQ_MAX) may follow, any other header closes it
 * (protocol +1); an unfinished frame leaves it waiting, an end of stream
 * closes it; an authenticated client has the HELLO queued and one answer
 * per complete REQUEST (this server serves none: "no requests served").
 */
#define _GNU_SOURCE
#include "telem_internal.h"

#include <string.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <unistd.h>

#include "fuzz_assert.h"

static const char fz_token[] = "fuzz-telemetry-token-0123456789ab";
static struct telem servers[2];	/* [0] without a token, [1] with one */

int LLVMFuzzerInitialize(int *argc, char ***argv);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerInitialize(int *argc, char ***argv)
{
	struct telem_cfg cfg;

	(void)argc;
	(void)argv;
	for (int i = 0; i < 2; i++) {
		telem_cfg_defaults(&cfg);
		cfg.port = 0;			/* loopback, any free port: never used */
		cfg.client_buffer = 64u * 1024u;
		cfg.token = i ? fz_token : NULL;
		cfg.token_len = i ? (uint32_t)strlen(fz_token) : 0u;
		if (telem_init(&servers[i], &cfg)) {
			fprintf(stderr, "fuzz_telem_client: telem_init failed\n");
			abort();
		}
	}
	return 0;
}

static int fz_pending(int fd)
{
	int n = 0;

	FZ_ASSERT(ioctl(fd, FIONREAD, &n) == 0);
	return n;
}

/* The server reads until the socket is empty or the client is gone. */
static void serve(struct telem *t, struct telem_client *c, int server_fd)
{
	for (int i = 0; i < 64 && c->fd >= 0; i++) {
		int before = fz_pending(server_fd), after;

		telem__client_read(t, c);
		if (c->fd < 0)
			return;
		after = fz_pending(server_fd);
		FZ_ASSERT(before - after <= (int)CLIENT_READ_MAX);
		if (after == 0)
			return;
	}
	FZ_ASSERT(c->fd < 0 || fz_pending(server_fd) == 0);
}

static void send_all(int fd, const uint8_t *p, size_t n)
{
	while (n) {
		ssize_t w = send(fd, p, n, MSG_NOSIGNAL);

		FZ_ASSERT(w > 0);
		p += w;
		n -= (size_t)w;
	}
}

/* What the server must have concluded from the bytes sent. */
enum verdict { V_WAITING, V_AUTHED, V_BAD_AUTH, V_PROTOCOL };

/* The answer the server (no request service here) queues at once for a
 * complete REQUEST. */
#define FZ_UNSERVED "no requests served"
#define FZ_REPLY_LEN (FRAME_HDR + REPLY_HDR + sizeof(FZ_UNSERVED) - 1u)

static enum verdict expected(const uint8_t *s, size_t n, int token, size_t *partial, size_t *requests)
{
	uint16_t type, flags;
	uint32_t len;
	size_t pos;

	*partial = n;
	*requests = 0;
	if (n < FRAME_HDR)
		return V_WAITING;
	memcpy(&type, s, 2);
	memcpy(&flags, s + 2, 2);
	memcpy(&len, s + 4, 4);
	if (type != TELEM_MSG_AUTH || flags || len > TELEM_TOKEN_MAX)
		return V_BAD_AUTH;
	if (n < FRAME_HDR + len)
		return V_WAITING;
	if (token && (len != strlen(fz_token) || memcmp(s + FRAME_HDR, fz_token, len)))
		return V_BAD_AUTH;
	/* then REQUEST frames only: a header that is not one closes the client */
	for (pos = FRAME_HDR + len; n - pos >= FRAME_HDR; pos += FRAME_HDR + len) {
		memcpy(&type, s + pos, 2);
		memcpy(&flags, s + pos + 2, 2);
		memcpy(&len, s + pos + 4, 4);
		if (type != TELEM_MSG_REQUEST || flags || len < 4u || len > 4u + TELEM_REQ_MAX)
			return V_PROTOCOL;
		if (n - pos < FRAME_HDR + len)
			break;
		(*requests)++;
	}
	*partial = n - pos;
	return V_AUTHED;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	static uint8_t sent[1u << 16];
	uint8_t flags = size ? data[0] : 0;
	struct telem *t = &servers[flags & 1u];
	struct telem_client *c = &t->clients[0];
	uint64_t failed0 = t->drop_auth_failed, proto0 = t->drop_protocol;
	size_t at = 1, n_sent = 0, partial, requests;
	enum verdict v;
	int sv[2];

	if (size > sizeof(sent) / 2u)
		return 0;
	FZ_ASSERT(socketpair(AF_UNIX, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0, sv) == 0);
	/* the slot as telem__accept_clients() leaves it */
	memset(c, 0, sizeof(*c));
	c->fd = sv[0];
	c->buf = malloc(t->cfg.client_buffer);
	FZ_ASSERT(c->buf);
	c->t_conn = c->t_progress = mono_now_ns();

	while (at < size && c->fd >= 0) {
		size_t n = data[at++];

		if (n > size - at)
			n = size - at;
		send_all(sv[1], data + at, n);
		memcpy(sent + n_sent, data + at, n);
		n_sent += n;
		at += n;
		serve(t, c, sv[0]);
	}
	if (c->fd >= 0 && (flags & 4u)) {
		uint8_t junk[5000];

		memset(junk, 0x41, sizeof(junk));
		send_all(sv[1], junk, sizeof(junk));
		memcpy(sent + n_sent, junk, sizeof(junk));
		n_sent += sizeof(junk);
		serve(t, c, sv[0]);
	}
	v = expected(sent, n_sent, flags & 1u, &partial, &requests);
	if (at < size)	/* closed before everything was sent: the verdict came early */
		FZ_ASSERT(v == V_BAD_AUTH || v == V_PROTOCOL);
	switch (v) {
	case V_WAITING:
		FZ_ASSERT(c->fd >= 0 && !c->authed && c->in_len == n_sent);
		FZ_ASSERT(t->drop_auth_failed == failed0 && t->drop_protocol == proto0);
		break;
	case V_AUTHED:
		/* the HELLO, then one immediate answer per complete REQUEST
		 * (or, with the buffer full, one lost event) */
		FZ_ASSERT(c->fd >= 0 && c->authed && c->in_len == partial);
		FZ_ASSERT(c->off == 0 && c->len >= FRAME_HDR + HELLO_LEN);
		FZ_ASSERT((c->len - FRAME_HDR - HELLO_LEN) % FZ_REPLY_LEN == 0);
		FZ_ASSERT((c->len - FRAME_HDR - HELLO_LEN) / FZ_REPLY_LEN + c->events_lost == requests);
		FZ_ASSERT(t->clients_now == 1);
		FZ_ASSERT(t->drop_auth_failed == failed0 && t->drop_protocol == proto0);
		break;
	case V_BAD_AUTH:
		FZ_ASSERT(c->fd < 0 && t->drop_auth_failed == failed0 + 1u);
		FZ_ASSERT(t->drop_protocol == proto0);
		break;
	case V_PROTOCOL:
		FZ_ASSERT(c->fd < 0 && t->drop_protocol == proto0 + 1u);
		FZ_ASSERT(t->drop_auth_failed == failed0);
		break;
	}
	FZ_ASSERT(c->in_len <= sizeof(c->in));
	if (c->fd >= 0 && (flags & 2u)) {
		shutdown(sv[1], SHUT_WR);
		telem__client_read(t, c);
		FZ_ASSERT(c->fd < 0);	/* an end of stream closes the client */
	}
	telem__client_close(t, c);
	FZ_ASSERT(t->clients_now == 0);
	close(sv[1]);
	return 0;
}
