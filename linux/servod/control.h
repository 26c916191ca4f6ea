/* SPDX-License-Identifier: MIT */
/*
 * control.h - the local control socket (protocol in servod.h): one request
 * line per connection, dispatched by its first word to a handler.
 *
 * Each handler is declared beside its code with SERVOD_REQUEST("name", fn):
 * the declaration puts {name, fn} in the linker section "servod_requests",
 * which control.c walks; there is no central list to edit. A handler gets
 * the request's words as argv (argv[0] is the request's name), appends its
 * body with put() and returns SE_OK, or an SE_* code with its message in
 * msg (the "ERR <code> <message>" line).
 */
#ifndef SERVOD_CONTROL_H
#define SERVOD_CONTROL_H

#include <stddef.h>

struct servod;

/* A growing answer body. */
struct out {
	char *buf;
	size_t len, cap;
};

void put(struct out *o, const char *fmt, ...) __attribute__((format(printf, 2, 3)));

typedef int request_fn(struct servod *sd, struct out *o, int argc, char **argv, char *msg, size_t n);

struct servod_request {
	const char *name;
	request_fn *fn;
};

#define SERVOD_REQUEST(name_, fn_)                                                          \
	static const struct servod_request servod_request_##fn_                             \
		__attribute__((used, section("servod_requests"), aligned(sizeof(void *)))) = \
		{ name_, fn_ }

/* The socket at sd->opt.sock_path: 0, or -1 (errno). */
int control_listen(struct servod *sd);
/* Serves the connection waiting on the socket, if any within timeout_ms. */
void control_serve(struct servod *sd, int timeout_ms);
void control_close(struct servod *sd);

#endif
