/* SPDX-License-Identifier: MIT */
/*
 * amp_config.h - every compile-time option of amp_lib, with its default.
 * Both sides MUST be built with the same values: the header written by
 * Linux records them and the servo refuses a region built differently.
 * The table in amp_lib/README.md documents each option.
 */
#ifndef AMP_CONFIG_H
#define AMP_CONFIG_H

/* Number of axes carried by the periodic records (1..32). */
#ifndef AMP_MAX_AXES
#define AMP_MAX_AXES 8
#endif

/* Mailbox payload capacity in bytes (multiple of 32, 32..16384). */
#ifndef AMP_MBOX_CAPACITY
#define AMP_MBOX_CAPACITY 512
#endif

/* Cache line size of the cores sharing the region (32 on A9 and R5). */
#ifndef AMP_CACHE_LINE
#define AMP_CACHE_LINE 32
#endif

/*
 * 1 if the region is mapped cacheable on this side: amp_lib then cleans
 * and invalidates the lines it writes/reads through the port's cache
 * hooks. 0 (default) for a non-cacheable / strongly-ordered mapping.
 */
#ifndef AMP_CFG_OCM_CACHED
#define AMP_CFG_OCM_CACHED 0
#endif

/*
 * How amp_lib computes the CRC-32 of the header and the mailbox frames (the
 * same CRC either way, bit for bit: only speed and size differ).
 * 1: slicing-by-4, four 256-entry tables (4 KiB of read-only data), one
 *    word of a frame in 4 table loads; 0: a 16-entry nibble table (64 B),
 *    8 dependent steps per word, for the servo firmware's 2 KiB code budget.
 * Default: 1 in a hosted build (Linux userspace, the host tests), 0 in a
 * freestanding one (the firmware is built with -ffreestanding). The one
 * option the two sides may set differently: the CRC is the same.
 */
#ifndef AMP_CFG_CRC_SLICE4
#if __STDC_HOSTED__
#define AMP_CFG_CRC_SLICE4 1
#else
#define AMP_CFG_CRC_SLICE4 0
#endif
#endif

/* Default watchdog limit, in cycles without a peer heartbeat. */
#ifndef AMP_WD_LIMIT_DEFAULT
#define AMP_WD_LIMIT_DEFAULT 10
#endif

#if AMP_MAX_AXES < 1 || AMP_MAX_AXES > 32
#error "AMP_MAX_AXES must be 1..32"
#endif
#if AMP_MBOX_CAPACITY < 32 || AMP_MBOX_CAPACITY > 16384 || (AMP_MBOX_CAPACITY % 32) != 0
#error "AMP_MBOX_CAPACITY must be a multiple of 32 in 32..16384"
#endif

#endif /* AMP_CONFIG_H */
