/* SPDX-License-Identifier: MIT */
/*
 * Bare-metal ARMv7-A (Cortex-A9) / ARMv7-R (Cortex-R5) port.
 *
 * The board/firmware provides:
 *   uint32_t amp_board_ticks(void);   free-running 32-bit counter
 *   #define AMP_BOARD_TICKS_PER_US    its rate (e.g. via -D or a header
 *                                     included with -include)
 * Shared words are accessed as volatile 32-bit loads/stores; DMB SY
 * orders them for the other core (OCM may be reached through different
 * interconnect paths, so the full-system domain is used). With
 * AMP_CFG_OCM_CACHED=1 the lines are maintained to the point of coherency
 * with DCCMVAC / DCIMVAC (L1 only: OCM is not behind the PL310 L2 when the
 * SCU's address filtering sends 0xFFFC0000.. to OCM directly).
 */
#ifndef AMP_PORT_IMPL_H
#define AMP_PORT_IMPL_H

#include <stdint.h>

#ifndef AMP_BOARD_TICKS_PER_US
#error "define AMP_BOARD_TICKS_PER_US for the bare-metal port"
#endif

uint32_t amp_board_ticks(void);

#define AMP_PORT_LOAD32(p)     (*(const volatile uint32_t *)(p))
#define AMP_PORT_STORE32(p, v) (*(volatile uint32_t *)(p) = (uint32_t)(v))
#define AMP_PORT_MB()          __asm__ volatile("dmb sy" ::: "memory")
#define AMP_PORT_WMB()         __asm__ volatile("dmb st" ::: "memory")
#define AMP_PORT_RELAX()       __asm__ volatile("nop" ::: "memory")
#define AMP_PORT_SIGNAL()      __asm__ volatile("dsb sy\n\tsev" ::: "memory")
#define AMP_PORT_TICKS_PER_US  (AMP_BOARD_TICKS_PER_US)

static inline uint32_t amp_port_ticks(void)
{
	return amp_board_ticks();
}

#if AMP_CFG_OCM_CACHED
static inline void amp_port__dcache_op(const volatile void *a, uint32_t n, int inval)
{
	uintptr_t p = (uintptr_t)a & ~(uintptr_t)(AMP_CACHE_LINE - 1);
	uintptr_t end = (uintptr_t)a + n;

	for (; p < end; p += AMP_CACHE_LINE) {
		if (inval)
			__asm__ volatile("mcr p15, 0, %0, c7, c6, 1" :: "r"(p) : "memory");
		else
			__asm__ volatile("mcr p15, 0, %0, c7, c10, 1" :: "r"(p) : "memory");
	}
	__asm__ volatile("dsb sy" ::: "memory");
}
#define AMP_PORT_CACHE_CLEAN(a, n) amp_port__dcache_op((a), (n), 0)
#define AMP_PORT_CACHE_INVAL(a, n) amp_port__dcache_op((a), (n), 1)
#else
#define AMP_PORT_CACHE_CLEAN(a, n) ((void)(a), (void)(n))
#define AMP_PORT_CACHE_INVAL(a, n) ((void)(a), (void)(n))
#endif

#endif /* AMP_PORT_IMPL_H */
