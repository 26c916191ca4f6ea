/* SPDX-License-Identifier: MIT */
/* Tick counter for the POSIX-hosted ports: CLOCK_MONOTONIC microseconds,
 * truncated to 32 bits (timeouts up to 35 minutes). Needs
 * _POSIX_C_SOURCE >= 199309L from the build. */
#ifndef AMP_PORT_CLOCK_MONOTONIC_H
#define AMP_PORT_CLOCK_MONOTONIC_H

#include <stdint.h>
#include <time.h>

#define AMP_PORT_TICKS_PER_US 1u

static inline uint32_t amp_port_ticks(void)
{
	struct timespec ts;

	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (uint32_t)((uint64_t)ts.tv_sec * 1000000u + (uint64_t)ts.tv_nsec / 1000u);
}

#endif /* AMP_PORT_CLOCK_MONOTONIC_H */
