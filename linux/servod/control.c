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

static void handle_client(struct servod *sd, int fd)
{
	char line[512], msg[512] = "", *argv[24], *save = 0, *tok;
	struct out o = { malloc(1024), 0, 1024 };
	const struct servod_request *req;
	int argc = 0, rc = SE_USAGE;
	ssize_t r = 0, got = 0;
	struct pollfd pfd = { fd, POLLIN, 0 };
	char head[600];

	while (got < (ssize_t)sizeof(line) - 1 && poll(&pfd, 1, 1000) > 0) {
		r = read(fd, line + got, sizeof(line) - 1 - (size_t)got);
		if (r <= 0)
			break;
		got += r;
		if (memchr(line, '\n', (size_t)got))
			break;
	}
	line[got] = 0;
	for (tok = strtok_r(line, " \t\r\n", &save); tok && argc < 24; tok = strtok_r(0, " \t\r\n", &save))
		argv[argc++] = tok;
	if (!argc)
		snprintf(msg, sizeof(msg), "empty request");
	else if (!(req = find_request(argv[0])))
		snprintf(msg, sizeof(msg), "unknown request '%s'", argv[0]);
	else
		rc = req->fn(sd, &o, argc, argv, msg, sizeof(msg));
	if (rc == SE_OK)
		snprintf(head, sizeof(head), "OK\n");
	else
		snprintf(head, sizeof(head), "ERR %d %s\n", rc, msg);
	if (write(fd, head, strlen(head)) < 0 || (o.len && write(fd, o.buf, o.len) < 0))
		logm(sd, "client write: %s", strerror(errno));
	free(o.buf);
}

int control_listen(struct servod *sd)
{
	struct sockaddr_un sa = { .sun_family = AF_UNIX };

	sd->listen_fd = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
	snprintf(sa.sun_path, sizeof(sa.sun_path), "%s", sd->opt.sock_path);
	unlink(sd->opt.sock_path);
	if (sd->listen_fd < 0 || bind(sd->listen_fd, (struct sockaddr *)&sa, sizeof(sa)) ||
	    listen(sd->listen_fd, 8))
		return -1;
	return 0;
}

void control_serve(struct servod *sd, int timeout_ms)
{
	struct pollfd pfd = { sd->listen_fd, POLLIN, 0 };

	if (poll(&pfd, 1, timeout_ms) > 0) {
		int cfd = accept4(sd->listen_fd, 0, 0, SOCK_CLOEXEC);

		if (cfd >= 0) {
			handle_client(sd, cfd);
			close(cfd);
		}
	}
}

void control_close(struct servod *sd)
{
	unlink(sd->opt.sock_path);
}
