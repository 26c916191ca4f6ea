/* SPDX-License-Identifier: GPL-2.0-only */
/* User-space stand-in for <linux/overflow.h>: struct_size() saturates at
 * SIZE_MAX on overflow, as the kernel's does. */
#ifndef KSHIM_LINUX_OVERFLOW_H
#define KSHIM_LINUX_OVERFLOW_H
#include <stdint.h>
#include <linux/types.h>

static inline size_t kshim_struct_size(size_t base, size_t elem, size_t n)
{
	size_t r;

	if (__builtin_mul_overflow(elem, n, &r) || __builtin_add_overflow(r, base, &r))
		return SIZE_MAX;
	return r;
}

#define struct_size(p, member, n) \
	kshim_struct_size(sizeof(*(p)), sizeof(*(p)->member), (size_t)(n))
#endif
