/* SPDX-License-Identifier: MIT */
#ifndef RPU_MMU_H
#define RPU_MMU_H

/* Build the section map from BOARD_MMU_REGIONS, enable MMU + L1 caches. */
void mmu_init(void);
int mmu_enabled(void);

#endif
