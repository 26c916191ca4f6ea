/* SPDX-License-Identifier: GPL-2.0-only */
/* User-space stand-in for <linux/firmware.h>: the image as the core hands
 * it to the driver. */
#ifndef KSHIM_LINUX_FIRMWARE_H
#define KSHIM_LINUX_FIRMWARE_H
#include <linux/types.h>

struct firmware {
	size_t size;
	const u8 *data;
};
#endif
