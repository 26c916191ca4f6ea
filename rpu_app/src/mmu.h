/* SPDX-License-Identifier: MIT */
#ifndef RPU_MMU_H
#define RPU_MMU_H

#include <stdint.h>

/* Build the section map from BOARD_MMU_REGIONS, enable MMU + L1 caches. */
void mmu_init(void);
int mmu_enabled(void);
/* The SVC stack's guard page(s) [start, end): no access once the MMU is
 * on (mmu.c); an access there is an SVC stack overflow. */
uint32_t mmu_stack_guard_start(void);
uint32_t mmu_stack_guard_end(void);

#endif
