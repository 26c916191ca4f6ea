/* SPDX-License-Identifier: MIT */
#ifndef RPU_MEMPROT_H
#define RPU_MEMPROT_H

#include <stdint.h>

/*
 * Memory protection and caches, per platform (platform/<soc>/): the A9's
 * MMU (flat section map, mmu.c) or the R5's PMSAv7 MPU (mpu.c). Either
 * maps only the regions of the servo devicetree (BOARD_MEMPROT_REGIONS),
 * shared memory non-cacheable, and makes the pages below the SVC stack a
 * no-access guard.
 */
void memprot_init(void);	/* map, then enable the L1 caches */
int memprot_enabled(void);
/* One line for the start-up log: what is mapped how. */
const char *memprot_describe(void);
/* The SVC stack's guard [start, end): no access once memprot_init() ran;
 * an access there is an SVC stack overflow. */
uint32_t memprot_stack_guard_start(void);
uint32_t memprot_stack_guard_end(void);

#endif
