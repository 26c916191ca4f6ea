/* SPDX-License-Identifier: MIT */
/*
 * POSIX host port: a MAP_SHARED mapping stands in for OCM between two
 * processes (or threads). C11-style atomics keep the accesses defined and
 * visible to ThreadSanitizer; ticks are CLOCK_MONOTONIC microseconds.
 */
#ifndef AMP_PORT_IMPL_H
#define AMP_PORT_IMPL_H

#include <stdint.h>

#if defined(AMP_PORT_TEST_LOAD_HOOK)
/*
 * Test builds only (tests/amp_lib/test_amp_hostile.c): every load from the
 * shared region goes through the test's hook, which sees the address and
 * the value read and may play the hostile peer (rewrite other words right
 * after this read), deterministically.
 */
uint32_t amp_port_test_load_hook(const uint32_t *p, uint32_t v);
#define AMP_PORT_LOAD32(p)   amp_port_test_load_hook((p), __atomic_load_n((p), __ATOMIC_RELAXED))
#define AMP_PORT_LOAD_ACQ(p) amp_port_test_load_hook((p), __atomic_load_n((p), __ATOMIC_ACQUIRE))
#else
#define AMP_PORT_LOAD32(p)     __atomic_load_n((p), __ATOMIC_RELAXED)
/* Semaphore and publication words: acquire / release. */
#define AMP_PORT_LOAD_ACQ(p)     __atomic_load_n((p), __ATOMIC_ACQUIRE)
#endif
#define AMP_PORT_STORE32(p, v) __atomic_store_n((p), (v), __ATOMIC_RELAXED)
#define AMP_PORT_STORE_REL(p, v) __atomic_store_n((p), (v), __ATOMIC_RELEASE)
#if defined(__SANITIZE_THREAD__)
/* ThreadSanitizer does not model fences: use a locked RMW (a full barrier
 * on x86) that it understands. Every shared access is atomic anyway. */
static uint32_t amp_port__tsan_fence __attribute__((unused));
#define AMP_PORT_MB() ((void)__atomic_fetch_add(&amp_port__tsan_fence, 0u, __ATOMIC_SEQ_CST))
#define AMP_PORT_RMB() AMP_PORT_MB()
#define AMP_PORT_WMB() AMP_PORT_MB()
#else
#define AMP_PORT_MB()          __atomic_thread_fence(__ATOMIC_SEQ_CST)
#define AMP_PORT_RMB()         __atomic_thread_fence(__ATOMIC_ACQUIRE)
#define AMP_PORT_WMB()         __atomic_thread_fence(__ATOMIC_RELEASE)
#endif
#define AMP_PORT_CACHE_CLEAN(a, n) ((void)(a), (void)(n))
#define AMP_PORT_CACHE_INVAL(a, n) ((void)(a), (void)(n))

#if defined(__x86_64__) || defined(__i386__)
#define AMP_PORT_RELAX() __builtin_ia32_pause()
#elif defined(__arm__) || defined(__aarch64__)
#define AMP_PORT_RELAX() __asm__ volatile("yield" ::: "memory")
#else
#define AMP_PORT_RELAX() do { } while (0)
#endif

#include "../common/amp_port_clock_monotonic.h"

#endif /* AMP_PORT_IMPL_H */
