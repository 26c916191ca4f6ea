/* SPDX-License-Identifier: MIT */
/* sysfs.h - one-line reads and writes of sysfs attributes. */
#ifndef SERVOD_SYSFS_H
#define SERVOD_SYSFS_H

#include <stddef.h>

/* The attribute's text without its trailing newline or blanks: 0, or -1 (errno). */
int sysfs_read(const char *path, char *buf, size_t n);
/* Writes s: 0, or -1 (errno). */
int sysfs_write(const char *path, const char *s);

#endif
