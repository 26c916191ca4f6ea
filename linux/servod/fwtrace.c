// SPDX-License-Identifier: MIT
/*
 * fwtrace.c - the firmware's trace lines as telemetry LOG "rpu_app"
 * (fwtrace.h). The buffer is circular and debugfs shows it up to its NUL
 * (the firmware's write position): new text is what lies beyond the part
 * already sent. When the part already sent is no longer there as it was
 * (shorter, or other bytes), the firmware wrapped or restarted (its
 * log_init clears the buffer): read it from the start again. Only whole
 * lines are sent.
 */
#define _GNU_SOURCE
#include <fcntl.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "context.h"

static uint32_t trace_level(const char *s, size_t n)
{
	if ((n >= 8 && !strncmp(s, "warning:", 8)) || memmem(s, n, "WARN", 4))
		return TELEM_LOG_WARNING;
	if (memmem(s, n, "FAULT", 5) || memmem(s, n, "fault:", 6) || memmem(s, n, "error", 5) ||
	    memmem(s, n, "CRASH", 5) || memmem(s, n, "crash", 5))
		return TELEM_LOG_ERROR;
	return TELEM_LOG_INFO;
}

/* Reads the buffer and sends the whole lines not sent yet. */
static void fwtrace_poll(struct servod *sd, struct fwtrace *t)
{
	ssize_t len = 0, r;
	int fd;

	if (!t->path[0] && rproc_trace_path(t->path, sizeof(t->path)))
		return;
	fd = open(t->path, O_RDONLY | O_CLOEXEC);
	if (fd < 0) {
		t->off = 0;	/* firmware stopped: its next run starts a new trace */
		return;
	}
	while (len < (ssize_t)sizeof(t->buf) - 1 &&
	       (r = read(fd, t->buf + len, sizeof(t->buf) - 1 - (size_t)len)) > 0)
		len += r;
	close(fd);
	if (len > 0 && t->buf[len - 1] == 0)
		len = (ssize_t)strnlen(t->buf, (size_t)len);
	if ((size_t)len < t->off || memcmp(t->buf, t->prev, t->off))
		t->off = 0;	/* wrapped or restarted */
	while (t->off < (size_t)len) {
		char *s = t->buf + t->off, *nl = memchr(s, '\n', (size_t)len - t->off);
		size_t n;

		if (!nl)
			break;	/* a line still being written */
		n = (size_t)(nl - s);
		if (n && telem_push_log(&sd->telem, 0, trace_level(s, n), "rpu_app", s, n))
			break;	/* event queue full: retry these lines next time */
		t->off += n + 1;
	}
	memcpy(t->prev, t->buf, t->off);
}

static void *fwtrace_thread(void *arg)
{
	struct servod *sd = arg;

	while (!servod_quitting(sd)) {
		struct timespec ts = { 0, 200 * 1000000L };

		nanosleep(&ts, 0);
		fwtrace_poll(sd, &sd->trace);
	}
	return 0;
}

int fwtrace_start(struct servod *sd)
{
	int rc = pthread_create(&sd->trace.th, 0, fwtrace_thread, sd);

	sd->trace.started = !rc;
	return rc;
}

void fwtrace_join(struct servod *sd)
{
	if (sd->trace.started)
		pthread_join(sd->trace.th, 0);
}
