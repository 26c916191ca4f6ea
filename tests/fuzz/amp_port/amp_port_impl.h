/* SPDX-License-Identifier: MIT */
/*
 * amp_lib port for the fuzz harness (tests/fuzz/fuzz_amp_ocm.c): a single
 * thread, OCM is a plain array, and the peer is the fuzzer. Every 32-bit
 * load from shared memory goes through fz_load(), which may let the
 * "peer" overwrite the word just before it is read (a crashed or hostile
 * core writes whenever it likes), and remembers what each word was read
 * as. The tick counter advances by one per call, so every bounded wait in
 * amp_lib ends after a known number of polls: a harness run never hangs
 * on time, only on a loop that is not bounded.
 */
#ifndef AMP_PORT_IMPL_H
#define AMP_PORT_IMPL_H

#include <stdint.h>

uint32_t fz_load(const volatile uint32_t *p);
uint32_t fz_ticks(void);

#define AMP_PORT_LOAD32(p)     fz_load((const volatile uint32_t *)(p))
#define AMP_PORT_STORE32(p, v) (*(volatile uint32_t *)(p) = (uint32_t)(v))
#define AMP_PORT_MB()          __atomic_signal_fence(__ATOMIC_SEQ_CST)
#define AMP_PORT_CACHE_CLEAN(a, n) ((void)(a), (void)(n))
#define AMP_PORT_CACHE_INVAL(a, n) ((void)(a), (void)(n))
#define AMP_PORT_RELAX()       do { } while (0)
#define AMP_PORT_TICKS_PER_US  1u

static inline uint32_t amp_port_ticks(void)
{
	return fz_ticks();
}

#endif /* AMP_PORT_IMPL_H */
