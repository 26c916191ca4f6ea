/* SPDX-License-Identifier: MIT */
/*
 * The monotonic clock, read in one place for the whole library: the
 * scheduler's release times and job timings, motion_wait()'s deadline and
 * the tests' timeouts.
 */
#ifndef SERVOAMP_MOTION_MONO_CLOCK_H
#define SERVOAMP_MOTION_MONO_CLOCK_H

#include <stdint.h>
#include <time.h>

/* Nanoseconds of CLOCK_MONOTONIC. */
static inline uint64_t mono_now_ns(void)
{
	struct timespec ts;

	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (uint64_t)ts.tv_sec * 1000000000u + (uint64_t)ts.tv_nsec;
}

/* Microseconds of CLOCK_MONOTONIC. */
static inline uint64_t mono_now_us(void)
{
	return mono_now_ns() / 1000u;
}

/* The CLOCK_MONOTONIC time delta_ns from now, as a pthread_cond_timedwait()
 * deadline (the condition variable must use CLOCK_MONOTONIC). */
static inline void mono_deadline(struct timespec *ts, uint64_t delta_ns)
{
	clock_gettime(CLOCK_MONOTONIC, ts);
	uint64_t ns = (uint64_t)ts->tv_nsec + delta_ns;
	ts->tv_sec += (time_t)(ns / 1000000000u);
	ts->tv_nsec = (long)(ns % 1000000000u);
}

#endif
