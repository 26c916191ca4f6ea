/* SPDX-License-Identifier: MIT */
/* sysfs.h - one-line reads and writes of sysfs attributes. */
#ifndef SERVOD_SYSFS_H
#define SERVOD_SYSFS_H

#include <stddef.h>

/* The attribute's text without its trailing newline or blanks: 0, or -1 (errno). */
int sysfs_read(const char *path, char *buf, size_t n);
/* Writes s: 0, or -1 (errno). */
int sysfs_write(const char *path, const char *s);

/* The first entry of /sys/class/CLASS named ENTRY_PREFIX* whose "name"
 * attribute is name (or starts with it: whole = 0): its directory name in
 * entry. 0, or -1 (none). */
int sysfs_class_find(const char *class, const char *entry_prefix, const char *name, int whole, char *entry,
		     size_t n);

#endif
