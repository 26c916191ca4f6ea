// SPDX-License-Identifier: MIT
/* uio.c - opening and mapping a UIO device by name (uio.h). */
#define _GNU_SOURCE
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
	char entry[256], path[600], buf[64];
	void *p;
	int fd;

	if (sysfs_class_find("uio", "uio", prefix, 0, entry, sizeof(entry)))
		return -1;
	snprintf(path, sizeof(path), "/sys/class/uio/%s/maps/map0/size", entry);
	if (sysfs_read(path, buf, sizeof(buf)))
		return -1;
	*size = (uint32_t)strtoul(buf, 0, 0);
	snprintf(path, sizeof(path), "/sys/class/uio/%s/maps/map0/offset", entry);
	*offs = sysfs_read(path, buf, sizeof(buf)) ? 0 : (uint32_t)strtoul(buf, 0, 0);
	snprintf(path, sizeof(path), "/dev/%s", entry);
	fd = open(path, O_RDWR | O_CLOEXEC);
	if (fd < 0)
		return -1;
	p = mmap(0, *size, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
	if (p == MAP_FAILED) {
		close(fd);
		return -1;
	}
	*base = p;
	logm(sd, "%s: %s, map0 %u bytes (offset 0x%x)", prefix, path, *size, *offs);
	return fd;
}
