/* SPDX-License-Identifier: GPL-2.0-only */
/* User-space stand-in for <linux/device.h>: dev_err() and friends check
 * their format against the arguments (as the kernel's do) and print only
 * when the harness asks (struct device.verbose). */
#ifndef KSHIM_LINUX_DEVICE_H
#define KSHIM_LINUX_DEVICE_H
#include <stdarg.h>
#include <stdio.h>

struct device {
	int verbose;
};

static inline __attribute__((format(printf, 2, 3)))
void kshim_dev_printk(const struct device *dev, const char *fmt, ...)
{
	va_list ap;

	if (!dev || !dev->verbose)
		return;
	va_start(ap, fmt);
	vfprintf(stderr, fmt, ap);
	va_end(ap);
}

#define dev_err(dev, ...)  kshim_dev_printk(dev, __VA_ARGS__)
#define dev_warn(dev, ...) kshim_dev_printk(dev, __VA_ARGS__)
#define dev_info(dev, ...) kshim_dev_printk(dev, __VA_ARGS__)
#define dev_dbg(dev, ...)  kshim_dev_printk(dev, __VA_ARGS__)
#endif
