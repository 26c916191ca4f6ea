// SPDX-License-Identifier: MIT
/* log.c - servod's log lines (log.h). */
#define _GNU_SOURCE
#include <stdarg.h>
#include <stdio.h>
#include <time.h>

#include "context.h"

static void vlogl(struct servod *sd, uint32_t level, int push, const char *fmt, va_list ap)
{
	struct timespec ts;
	char line[TELEM_LOG_MAX];
	int n;

	clock_gettime(CLOCK_MONOTONIC, &ts);
	n = vsnprintf(line, sizeof(line), fmt, ap);
	fprintf(stderr, "servod[%ld.%03ld]: %s\n", (long)ts.tv_sec, ts.tv_nsec / 1000000, line);
	if (push && sd->telem_on && n > 0)
		telem_push_log(&sd->telem, 0, level, "servod", line,
			       (size_t)n < sizeof(line) ? (size_t)n : sizeof(line) - 1);
}

void logm(struct servod *sd, const char *fmt, ...)
{
	va_list ap;

	va_start(ap, fmt);
	vlogl(sd, TELEM_LOG_INFO, 1, fmt, ap);
	va_end(ap);
}

void logw(struct servod *sd, const char *fmt, ...)
{
	va_list ap;

	va_start(ap, fmt);
	vlogl(sd, TELEM_LOG_WARNING, 1, fmt, ap);
	va_end(ap);
}

void log_rt(struct servod *sd, const char *fmt, ...)
{
	va_list ap;

	va_start(ap, fmt);
	vlogl(sd, TELEM_LOG_INFO, 0, fmt, ap);
	va_end(ap);
}
