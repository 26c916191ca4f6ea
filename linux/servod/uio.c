// SPDX-License-Identifier: MIT
/* uio.c - opening and mapping a UIO device by name (uio.h). */
#define _GNU_SOURCE
#include <dirent.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

#include "context.h"

int uio_open(struct servod *sd, const char *prefix, volatile uint8_t **base, uint32_t *size,
	     uint32_t *offs)
{
	DIR *d = opendir("/sys/class/uio");
	struct dirent *e;
	char path[600], buf[64];
	int fd = -1;

	if (!d)
		return -1;
	while ((e = readdir(d))) {
		if (strncmp(e->d_name, "uio", 3))
			continue;
		snprintf(path, sizeof(path), "/sys/class/uio/%s/name", e->d_name);
		if (sysfs_read(path, buf, sizeof(buf)) || strncmp(buf, prefix, strlen(prefix)))
			continue;
		snprintf(path, sizeof(path), "/sys/class/uio/%s/maps/map0/size", e->d_name);
		if (sysfs_read(path, buf, sizeof(buf)))
			break;
		*size = (uint32_t)strtoul(buf, 0, 0);
		snprintf(path, sizeof(path), "/sys/class/uio/%s/maps/map0/offset", e->d_name);
		*offs = sysfs_read(path, buf, sizeof(buf)) ? 0 : (uint32_t)strtoul(buf, 0, 0);
		snprintf(path, sizeof(path), "/dev/%s", e->d_name);
		fd = open(path, O_RDWR | O_CLOEXEC);
		if (fd < 0)
			break;
		void *p = mmap(0, *size, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
		if (p == MAP_FAILED) {
			close(fd);
			fd = -1;
			break;
		}
		*base = p;
		logm(sd, "%s: %s, map0 %u bytes (offset 0x%x)", prefix, path, *size, *offs);
		break;
	}
	closedir(d);
	return fd;
}
