/* SPDX-License-Identifier: MIT */
/*
 * fwtrace.h - the firmware's trace buffer (remoteproc debugfs trace0)
 * forwarded line by line as telemetry LOG "rpu_app", by a normal-priority
 * thread every 200 ms (only while telemetry is on).
 */
#ifndef SERVOD_FWTRACE_H
#define SERVOD_FWTRACE_H

#include <pthread.h>
#include <stddef.h>

struct servod;

#define FWTRACE_BUF (64 * 1024)

struct fwtrace {
	pthread_t th;
	int started;
	char path[600];		/* debugfs trace0, "" until the instance is found */
	size_t off;		/* bytes of the buffer already sent */
	char buf[FWTRACE_BUF], prev[FWTRACE_BUF];
};

/* 0, or the pthread_create error. */
int fwtrace_start(struct servod *sd);
void fwtrace_join(struct servod *sd);

#endif
