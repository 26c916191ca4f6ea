/* SPDX-License-Identifier: MIT */
/*
 * control.h - the local control socket (protocol in servod.h): one request
 * line per connection, dispatched by its first word to a handler.
 *
 * The socket never makes the main thread wait on a client: the listening
 * socket and the connections are non-blocking and served from the main
 * loop's poll() (control_serve) between two rounds of the supervisor. A
 * connection has CONTROL_REQUEST_MS from its accept to send its whole
 * request line (a total deadline: bytes arriving do not extend it), else it
 * is answered "ERR 1 ..." and closed; CONTROL_CLIENTS connections may be
 * collecting their line at once (more are answered "ERR 10 ..."). The
 * answer is written without waiting (a client that does not read it loses
 * it). Who may connect: the peer's credentials (SO_PEERCRED) say root or
 * servod's own uid; anyone else is answered "ERR 11 ..." and the refusal is
 * logged. The socket file is made 0666 so that this check, not the file
 * mode, is the one gate (and every refusal is seen and logged).
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
#include <stdint.h>
#include <sys/types.h>

struct servod;

#define CONTROL_CLIENTS 4	/* connections collecting their request line at once */
#define CONTROL_LINE 512	/* request line, with its newline */
#define CONTROL_REQUEST_MS 1000	/* from accept to the whole line */

/* A connection collecting its request line (fd -1: free). */
struct control_client {
	int fd;
	size_t got;
	uint64_t deadline_ns;	/* mono_now_ns() at accept + CONTROL_REQUEST_MS */
	char line[CONTROL_LINE];
};

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

/* 1 if a peer with this uid may use the socket of a servod running as
 * self_uid: root, or servod's own uid. */
int control_peer_allowed(uid_t peer_uid, uid_t self_uid);
/* The socket at sd->opt.sock_path (non-blocking, mode 0666): 0, or -1 (errno). */
int control_listen(struct servod *sd);
/* Waits up to timeout_ms for the socket or a connection, then takes what
 * is there without waiting: new connections, bytes of request lines,
 * complete requests (dispatched), deadlines passed. */
void control_serve(struct servod *sd, int timeout_ms);
void control_close(struct servod *sd);

#endif
