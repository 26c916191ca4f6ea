/* SPDX-License-Identifier: MIT */
/*
 * log.h - servod's log lines: stderr ("servod[SEC.MS]: ..."), and the
 * telemetry's LOG events ("servod") when telemetry is on.
 */
#ifndef SERVOD_LOG_H
#define SERVOD_LOG_H

struct servod;

#define SERVOD_PRINTF(f, a) __attribute__((format(printf, f, a)))

/* Information and warnings, from any thread but the cycle thread. */
void logm(struct servod *sd, const char *fmt, ...) SERVOD_PRINTF(2, 3);
void logw(struct servod *sd, const char *fmt, ...) SERVOD_PRINTF(2, 3);
/* From the cycle thread: stderr only (the telemetry's event queue takes a mutex). */
void log_rt(struct servod *sd, const char *fmt, ...) SERVOD_PRINTF(2, 3);

#endif
