/* SPDX-License-Identifier: MIT */
/*
 * Linux userspace port for the target (Cortex-A9 / A53 Linux): OCM is an
 * mmap()ed UIO region, mapped non-cacheable by the kernel, so no cache
 * maintenance is needed; the barriers must order accesses for the other
 * core, which on ARM means a full-system DMB (the servo core may sit
 * outside the inner-shareable domain, e.g. the ZynqMP R5).
 */
#ifndef AMP_PORT_IMPL_H
#define AMP_PORT_IMPL_H

#include <stdint.h>

#define AMP_PORT_LOAD32(p)     __atomic_load_n((p), __ATOMIC_RELAXED)
#define AMP_PORT_STORE32(p, v) __atomic_store_n((p), (v), __ATOMIC_RELAXED)

#if defined(__arm__)
#define AMP_PORT_MB()    __asm__ volatile("dmb sy" ::: "memory")
#define AMP_PORT_WMB()   __asm__ volatile("dmb st" ::: "memory")
#define AMP_PORT_RELAX() __asm__ volatile("yield" ::: "memory")
#elif defined(__aarch64__)
#define AMP_PORT_MB()    __asm__ volatile("dmb sy" ::: "memory")
#define AMP_PORT_RMB()   __asm__ volatile("dmb ld" ::: "memory")
#define AMP_PORT_WMB()   __asm__ volatile("dmb st" ::: "memory")
#define AMP_PORT_RELAX() __asm__ volatile("yield" ::: "memory")
#else
#define AMP_PORT_MB()    __atomic_thread_fence(__ATOMIC_SEQ_CST)
#define AMP_PORT_RELAX() do { } while (0)
#endif

#if AMP_CFG_OCM_CACHED
#error "the linux port expects a non-cacheable mapping (UIO maps OCM uncached)"
#endif
#define AMP_PORT_CACHE_CLEAN(a, n) ((void)(a), (void)(n))
#define AMP_PORT_CACHE_INVAL(a, n) ((void)(a), (void)(n))

#include "../common/amp_port_clock_monotonic.h"

#endif /* AMP_PORT_IMPL_H */
