/* SPDX-License-Identifier: MIT */
/*
 * fuzz_assert.h - what a harness checks: FZ_ASSERT(c) prints where and what
 * failed, then aborts, which libFuzzer reports as a finding (a plain
 * assert() would vanish under -DNDEBUG).
 */
#ifndef FUZZ_ASSERT_H
#define FUZZ_ASSERT_H

#include <stdio.h>
#include <stdlib.h>

#define FZ_ASSERT(c)                                                           \
	do {                                                                   \
		if (!(c)) {                                                    \
			fprintf(stderr, "%s:%d: %s\n", __FILE__, __LINE__, #c); \
			abort();                                               \
		}                                                              \
	} while (0)

#endif
