// SPDX-License-Identifier: MIT
/* control.c - the local control socket and the request dispatch (control.h). */
#define _GNU_SOURCE
#include <errno.h>
#include <poll.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include "context.h"

/* The handlers' declarations (SERVOD_REQUEST), collected by the linker. */
extern const struct servod_request __start_servod_requests[];
extern const struct servod_request __stop_servod_requests[];

void put(struct out *o, const char *fmt, ...)
{
	va_list ap;
	int n;

	for (;;) {
		va_start(ap, fmt);
		n = vsnprintf(o->buf + o->len, o->cap - o->len, fmt, ap);
		va_end(ap);
		if (n >= 0 && o->len + (size_t)n < o->cap)
			break;
		o->cap = o->cap * 2 + (size_t)(n > 0 ? n : 0);
		o->buf = realloc(o->buf, o->cap);
	}
	o->len += (size_t)n;
}

static const struct servod_request *find_request(const char *name)
{
	for (const struct servod_request *r = __start_servod_requests; r < __stop_servod_requests; r++)
		if (!strcmp(r->name, name))
			return r;
	return 0;
}

/* Writes what the socket takes now: a client that does not read its
 * answer loses it (its socket buffer holds any normal answer). */
static void send_now(struct servod *sd, int fd, const char *p, size_t n)
{
	while (n) {
		ssize_t w = send(fd, p, n, MSG_NOSIGNAL | MSG_DONTWAIT);

		if (w < 0 && errno == EINTR)
			continue;
		if (w <= 0) {
			logm(sd, "control: answer not taken by the client (%s): dropped",
			     w < 0 ? strerror(errno) : "closed");
			return;
		}
		p += w;
		n -= (size_t)w;
	}
}

static void send_error(struct servod *sd, int fd, int rc, const char *msg)
{
	char head[CONTROL_LINE + 64];

	snprintf(head, sizeof(head), "ERR %d %s\n", rc, msg);
	send_now(sd, fd, head, strlen(head));
}

/* The request in c->line[0..got): dispatched, answered. */
static void dispatch(struct servod *sd, struct control_client *c)
{
	char msg[512] = "", *argv[24], *save = 0, *tok;
	struct out o = { malloc(1024), 0, 1024 };
	const struct servod_request *req;
	int argc = 0, rc = SE_USAGE;

	c->line[c->got] = 0;
	for (tok = strtok_r(c->line, " \t\r\n", &save); tok && argc < 24; tok = strtok_r(0, " \t\r\n", &save))
		argv[argc++] = tok;
	if (!argc)
		snprintf(msg, sizeof(msg), "empty request");
	else if (!(req = find_request(argv[0])))
		snprintf(msg, sizeof(msg), "unknown request '%s'", argv[0]);
	else
		rc = req->fn(sd, &o, argc, argv, msg, sizeof(msg));
	if (rc == SE_OK)
		send_now(sd, c->fd, "OK\n", 3);
	else
		send_error(sd, c->fd, rc, msg);
	if (o.len)	/* a body comes with errors too ("status" when the servo is offline) */
		send_now(sd, c->fd, o.buf, o.len);
	free(o.buf);
}

static void drop(struct control_client *c)
{
	close(c->fd);
	c->fd = -1;
	c->got = 0;
}

/* Takes what the connection has sent (one read, never waits); dispatches
 * once the line is complete (newline, full, or the client's EOF). */
static void client_read(struct servod *sd, struct control_client *c)
{
	ssize_t r = read(c->fd, c->line + c->got, CONTROL_LINE - 1 - c->got);

	if (r < 0 && (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR))
		return;
	if (r > 0) {
		c->got += (size_t)r;
		if (!memchr(c->line, '\n', c->got) && c->got < CONTROL_LINE - 1)
			return;
	}
	if (r >= 0)
		dispatch(sd, c);
	drop(c);
}

int control_peer_allowed(uid_t peer_uid, uid_t self_uid)
{
	return peer_uid == 0 || peer_uid == self_uid;
}

/* A new connection: its credentials, then a free slot. */
static void client_accept(struct servod *sd, int fd)
{
	struct ucred cr;
	socklen_t len = sizeof(cr);
	uid_t self = geteuid();
	char msg[160];

	if (getsockopt(fd, SOL_SOCKET, SO_PEERCRED, &cr, &len) || len != sizeof(cr)) {
		logw(sd, "control: connection refused: no peer credentials (%s)", strerror(errno));
		close(fd);
		return;
	}
	if (!control_peer_allowed(cr.uid, self)) {
		logw(sd, "control: connection refused: uid %u (pid %d) is neither root nor servod's uid %u",
		     (unsigned)cr.uid, (int)cr.pid, (unsigned)self);
		snprintf(msg, sizeof(msg), "permission denied: only root and uid %u may use servod's socket",
			 (unsigned)self);
		send_error(sd, fd, SE_DENIED, msg);
		close(fd);
		return;
	}
	for (int i = 0; i < CONTROL_CLIENTS; i++) {
		struct control_client *c = &sd->clients[i];

		if (c->fd < 0) {
			c->fd = fd;
			c->got = 0;
			c->deadline_ns = mono_now_ns() + CONTROL_REQUEST_MS * 1000000ull;
			return;
		}
	}
	logw(sd, "control: connection refused: %d requests already being received", CONTROL_CLIENTS);
	send_error(sd, fd, SE_BUSY, "servod busy: too many connections sending their request");
	close(fd);
}

int control_listen(struct servod *sd)
{
	struct sockaddr_un sa = { .sun_family = AF_UNIX };

	for (int i = 0; i < CONTROL_CLIENTS; i++)
		sd->clients[i].fd = -1;
	sd->listen_fd = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0);
	snprintf(sa.sun_path, sizeof(sa.sun_path), "%s", sd->opt.sock_path);
	/* a stale socket of a dead servod; a live one holds the board lock
	 * (main.c), so this servod would not have come this far */
	unlink(sd->opt.sock_path);
	if (sd->listen_fd < 0 || bind(sd->listen_fd, (struct sockaddr *)&sa, sizeof(sa)) ||
	    chmod(sd->opt.sock_path, 0666) || listen(sd->listen_fd, 8))
		return -1;
	return 0;
}

void control_serve(struct servod *sd, int timeout_ms)
{
	struct pollfd pfd[1 + CONTROL_CLIENTS];
	struct control_client *slot[1 + CONTROL_CLIENTS];
	uint64_t now = mono_now_ns();
	nfds_t n = 1;

	pfd[0] = (struct pollfd){ sd->listen_fd, POLLIN, 0 };
	for (int i = 0; i < CONTROL_CLIENTS; i++) {
		struct control_client *c = &sd->clients[i];
		int64_t left;

		if (c->fd < 0)
			continue;
		left = (int64_t)(c->deadline_ns - now) / 1000000;
		if (left < timeout_ms)
			timeout_ms = left < 0 ? 0 : (int)left;
		slot[n] = c;
		pfd[n++] = (struct pollfd){ c->fd, POLLIN, 0 };
	}
	if (poll(pfd, n, timeout_ms) < 0)
		return;
	for (nfds_t k = 1; k < n; k++)
		if (pfd[k].revents)
			client_read(sd, slot[k]);
	now = mono_now_ns();
	for (int i = 0; i < CONTROL_CLIENTS; i++) {
		struct control_client *c = &sd->clients[i];

		if (c->fd >= 0 && (int64_t)(now - c->deadline_ns) >= 0) {
			logw(sd, "control: no whole request line within %d ms (%zu bytes): connection dropped",
			     CONTROL_REQUEST_MS, c->got);
			send_error(sd, c->fd, SE_USAGE, "no whole request line within the time allowed");
			drop(c);
		}
	}
	if (pfd[0].revents & POLLIN) {
		for (int i = 0; i < 8; i++) {	/* the backlog, a few at a time */
			int cfd = accept4(sd->listen_fd, 0, 0, SOCK_CLOEXEC | SOCK_NONBLOCK);

			if (cfd < 0)
				break;
			client_accept(sd, cfd);
		}
	}
}

void control_close(struct servod *sd)
{
	for (int i = 0; i < CONTROL_CLIENTS; i++)
		if (sd->clients[i].fd >= 0)
			drop(&sd->clients[i]);
	unlink(sd->opt.sock_path);
}
