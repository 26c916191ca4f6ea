/* SPDX-License-Identifier: GPL-2.0-only */
/* User-space stand-in for <linux/align.h>. */
#ifndef KSHIM_LINUX_ALIGN_H
#define KSHIM_LINUX_ALIGN_H
#define IS_ALIGNED(x, a) (((x) & ((__typeof__(x))(a) - 1)) == 0)
#endif
