// SPDX-License-Identifier: MIT
/*
 * ampctl - command line client of servod (local Unix socket).
 *
 *   ampctl [-s SOCKET] status
 *   ampctl [-s SOCKET] stats
 *   ampctl [-s SOCKET] param list
 *   ampctl [-s SOCKET] param get NAME|ID
 *   ampctl [-s SOCKET] param set NAME|ID VALUE
 *   ampctl [-s SOCKET] resume               leave SAFESTOP; acknowledge drive faults
 *   ampctl [-s SOCKET] fault                the recovery state and the fault latch
 *   ampctl [-s SOCKET] fault reset          reset a latched fault: the firmware restarted
 *   ampctl [-s SOCKET] debug hang|crash|fault|badparam|stack|overload|stray-irq|slow US  make the firmware fail (tests)
 *   ampctl [-s SOCKET] raw CMD NBYTES [WORD...]   raw mailbox request (tests)
 *   ampctl [-s SOCKET] run FILE.nc          run a G-code program (path as servod sees it)
 *   ampctl [-s SOCKET] stop                 decelerate along the path and hold
 *   ampctl [-s SOCKET] -                    the request line from standard input,
 *                                           sent as it arrives (scripts, tests)
 *
 * Exit status: 0 ok, 1 usage, 2 servod not reachable, 3 servo not running,
 * 4 timeout, 5 unknown parameter, 6 bad value (type/range), 7 other servo
 * error, 8 servod could not store the parameter file, 9 program refused
 * (unreadable or malformed: file:line:column: error), 10 a program is
 * already running (or servod has too many connections), 11 permission
 * denied (only root and servod's uid may) (linux/servod/servod.h).
 */
#define _GNU_SOURCE
#include <errno.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include "servod.h"

int main(int argc, char **argv)
{
	const char *path = SERVOD_SOCKET;
	struct sockaddr_un sa = { .sun_family = AF_UNIX };
	char req[512] = "", buf[4096], *body;
	size_t len = 0, used = 0;
	int fd, i = 1, code;
	ssize_t r;
	char *all = 0;
	int from_stdin;

	if (argc > 2 && !strcmp(argv[1], "-s")) {
		path = argv[2];
		i = 3;
	}
	if (i >= argc || !strcmp(argv[i], "-h") || !strcmp(argv[i], "--help")) {
		fprintf(stderr, "usage: ampctl [-s SOCKET] status | stats | param list | param get NAME |\n"
				"              param set NAME VALUE | resume | fault [reset] | debug hang|crash|fault|badparam|stack|overload|stray-irq|slow US |\n"
				"              raw CMD NBYTES [WORD...] | run FILE.nc | stop | -   (the request from standard input)\n");
		return SE_USAGE;
	}
	from_stdin = i == argc - 1 && !strcmp(argv[i], "-");
	if (from_stdin)
		i = argc;
	for (int first = i; i < argc; i++) {
		const char *a = argv[i];
		char abs[4096];
		int n;

		/* run FILE: servod opens it, so send an absolute path */
		if (i == first + 1 && !strcmp(argv[first], "run") && a[0] != '/' && realpath(a, abs))
			a = abs;
		n = snprintf(req + len, sizeof(req) - len, "%s%s", len ? " " : "", a);

		if (n < 0 || (size_t)n >= sizeof(req) - len) {
			fprintf(stderr, "ampctl: request too long\n");
			return SE_USAGE;
		}
		len += (size_t)n;
	}
	if (!from_stdin)
		req[len++] = '\n';

	signal(SIGPIPE, SIG_IGN);	/* servod may close before all is sent: its answer says why */
	fd = socket(AF_UNIX, SOCK_STREAM, 0);
	snprintf(sa.sun_path, sizeof(sa.sun_path), "%s", path);
	if (fd < 0 || connect(fd, (struct sockaddr *)&sa, sizeof(sa))) {
		fprintf(stderr, "ampctl: servod not reachable at %s: %s\n", path, strerror(errno));
		return SE_NOSERVOD;
	}
	if (from_stdin) {
		/* copy as it arrives, until EOF or servod stops taking it */
		while ((r = read(0, buf, sizeof(buf))) > 0)
			if (write(fd, buf, (size_t)r) != r)
				break;
	} else if (write(fd, req, len) != (ssize_t)len && errno != EPIPE && errno != ECONNRESET) {
		/* EPIPE/ECONNRESET: servod refused the connection and closed
		 * it, and its answer, read below, says why */
		fprintf(stderr, "ampctl: write: %s\n", strerror(errno));
	}
	shutdown(fd, SHUT_WR);
	while ((r = read(fd, buf, sizeof(buf))) > 0) {
		all = realloc(all, used + (size_t)r + 1);
		memcpy(all + used, buf, (size_t)r);
		used += (size_t)r;
	}
	close(fd);
	if (!all) {
		fprintf(stderr, "ampctl: servod closed the connection without an answer\n");
		return SE_NOSERVOD;
	}
	all[used] = 0;
	body = strchr(all, '\n');
	body = body ? body + 1 : all + used;
	fputs(body, stdout);
	if (!strncmp(all, "OK\n", 3))
		return SE_OK;
	if (sscanf(all, "ERR %d", &code) == 1) {
		char *msg = strchr(all + 4, ' ');
		char *nl = strchr(all, '\n');

		if (nl)
			*nl = 0;
		fprintf(stderr, "ampctl: %s\n", msg ? msg + 1 : "error");
		return code > 0 ? code : SE_SERVO;
	}
	fprintf(stderr, "ampctl: unexpected answer from servod\n");
	return SE_SERVO;
}
