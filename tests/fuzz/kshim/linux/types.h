/* SPDX-License-Identifier: GPL-2.0-only */
/* User-space stand-in for <linux/types.h>: only what the servo core driver's
 * image checks (linux/remoteproc/zynq_servo_rproc_check.h) use. */
#ifndef KSHIM_LINUX_TYPES_H
#define KSHIM_LINUX_TYPES_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

typedef uint8_t u8;
typedef uint16_t u16;
typedef uint32_t u32;
typedef unsigned long long u64;	/* as the kernel's: printed with %llx */
typedef int32_t s32;

#define __packed __attribute__((__packed__))

#endif
