/* SPDX-License-Identifier: MIT */
/*
 * mono_clock.h - the monotonic clock of servoamp's Linux programs, one
 * definition: servod (cycle times, timeouts), the telemetry transport, the
 * motion library (the scheduler's release times, motion_wait()'s deadline),
 * the benches and the tests.
 *
 * POSIX user space only (not the kernel, not the firmware): the including
 * file defines _POSIX_C_SOURCE >= 199309L (or _GNU_SOURCE) before its
 * first system header, for clock_gettime().
 */
#ifndef SERVOAMP_MONO_CLOCK_H
#define SERVOAMP_MONO_CLOCK_H

#if defined(__KERNEL__)
#error "servoamp/mono_clock.h is for user space (the kernel has ktime_get_ns)"
#endif

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
