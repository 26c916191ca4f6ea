// SPDX-License-Identifier: MIT
/* sysfs.c - one-line reads and writes of sysfs attributes (sysfs.h). */
#define _GNU_SOURCE
#include <dirent.h>
#include <fcntl.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

#include "sysfs.h"

int sysfs_read(const char *path, char *buf, size_t n)
{
	int fd = open(path, O_RDONLY);
	ssize_t r;

	if (fd < 0)
		return -1;
	r = read(fd, buf, n - 1);
	close(fd);
	if (r < 0)
		return -1;
	buf[r] = 0;
	while (r > 0 && (buf[r - 1] == '\n' || buf[r - 1] == ' '))
		buf[--r] = 0;
	return 0;
}

int sysfs_write(const char *path, const char *s)
{
	/* O_TRUNC as the shell's ">": nothing to sysfs, the whole value to a
	 * regular file (the tests' stand-in for remoteproc) */
	int fd = open(path, O_WRONLY | O_TRUNC);
	ssize_t r;

	if (fd < 0)
		return -1;
	r = write(fd, s, strlen(s));
	close(fd);
	return r < 0 ? -1 : 0;
}

int sysfs_class_find(const char *class, const char *entry_prefix, const char *name, int whole, char *entry,
		     size_t n)
{
	char path[600], buf[64];
	struct dirent *e;
	DIR *d;
	int rc = -1;

	snprintf(path, sizeof(path), "/sys/class/%s", class);
	d = opendir(path);
	if (!d)
		return -1;
	while ((e = readdir(d))) {
		if (strncmp(e->d_name, entry_prefix, strlen(entry_prefix)))
			continue;
		snprintf(path, sizeof(path), "/sys/class/%s/%s/name", class, e->d_name);
		if (sysfs_read(path, buf, sizeof(buf)))
			continue;
		if (whole ? !strcmp(buf, name) : !strncmp(buf, name, strlen(name))) {
			snprintf(entry, n, "%s", e->d_name);
			rc = 0;
			break;
		}
	}
	closedir(d);
	return rc;
}
