// SPDX-License-Identifier: MIT
/* rproc.c - the servo core's remoteproc instance in sysfs (rproc.h). */
#define _GNU_SOURCE
#include <dirent.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

#include "rproc.h"
#include "sysfs.h"

/* A devicetree cell (big-endian u32 in /sys/.../of_node): 0, or -1. */
static int of_cell(const char *path, uint32_t *v)
{
	unsigned char b[4];
	FILE *f = fopen(path, "rb");
	size_t got;

	if (!f)
		return -1;
	got = fread(b, 1, sizeof(b), f);
	fclose(f);
	if (got != sizeof(b))
		return -1;
	*v = (uint32_t)b[0] << 24 | (uint32_t)b[1] << 16 | (uint32_t)b[2] << 8 | b[3];
	return 0;
}

/* The phandle the OCM mailbox's devicetree node names as its remoteproc
 * (servoamp,remoteproc): 0, or -1 (no mailbox device, no such property). */
static int mailbox_rproc_phandle(uint32_t *ph)
{
	char entry[256], path[600];

	if (sysfs_class_find("uio", "uio", RPROC_MAILBOX_UIO, 0, entry, sizeof(entry)))
		return -1;
	snprintf(path, sizeof(path), "/sys/class/uio/%s/device/of_node/servoamp,remoteproc", entry);
	return of_cell(path, ph);
}

/* The remoteproc entry whose device's devicetree node has phandle ph. */
static int rproc_by_phandle(uint32_t ph, char *entry, size_t n)
{
	DIR *d = opendir("/sys/class/remoteproc");
	struct dirent *e;
	char path[600];
	uint32_t v;
	int rc = -1;

	if (!d)
		return -1;
	while ((e = readdir(d))) {
		if (strncmp(e->d_name, "remoteproc", 10))
			continue;
		snprintf(path, sizeof(path), "/sys/class/remoteproc/%s/device/of_node/phandle", e->d_name);
		if (!of_cell(path, &v) && v == ph) {
			snprintf(entry, n, "%s", e->d_name);
			rc = 0;
			break;
		}
	}
	closedir(d);
	return rc;
}

int rproc_lookup(char *entry, size_t n)
{
	uint32_t ph;

	if (!mailbox_rproc_phandle(&ph))
		return rproc_by_phandle(ph, entry, n);
	return sysfs_class_find("remoteproc", "remoteproc", RPROC_NAME, 1, entry, n);
}

int rproc_find(struct rproc *rp)
{
	char entry[256];

	if (rproc_lookup(entry, sizeof(entry)))
		return -1;
	snprintf(rp->dir, sizeof(rp->dir), "/sys/class/remoteproc/%s", entry);
	return 0;
}

const char *rproc_state(struct rproc *rp)
{
	char path[600];

	if (!rp->dir[0] && rproc_find(rp))
		return "absent";
	snprintf(path, sizeof(path), "%s/state", rp->dir);
	if (sysfs_read(path, rp->state, sizeof(rp->state))) {
		rp->dir[0] = 0;	/* driver unloaded? look again next time */
		return "absent";
	}
	return rp->state;
}

int rproc_has(const struct rproc *rp, const char *attr)
{
	char path[600];

	snprintf(path, sizeof(path), "%s/%s", rp->dir, attr);
	return access(path, F_OK) == 0;
}

int rproc_report_crash(const struct rproc *rp, char *path, size_t n)
{
	snprintf(path, n, "%s/device/report_crash", rp->dir);
	return sysfs_write(path, "watchdog");
}

int rproc_write_state(const struct rproc *rp, const char *what, char *path, size_t n)
{
	snprintf(path, n, "%s/state", rp->dir);
	return sysfs_write(path, what);
}

int rproc_write_recovery(const struct rproc *rp, const char *what, char *path, size_t n)
{
	snprintf(path, n, "%s/recovery", rp->dir);
	return sysfs_write(path, what);
}

int rproc_read_recovery(const struct rproc *rp, char *buf, size_t bn, char *path, size_t n)
{
	snprintf(path, n, "%s/recovery", rp->dir);
	return sysfs_read(path, buf, bn);
}

int rproc_trace_path(char *path, size_t n)
{
	char entry[256];

	if (rproc_lookup(entry, sizeof(entry)))
		return -1;
	snprintf(path, n, "/sys/kernel/debug/remoteproc/%s/trace0", entry);
	return 0;
}
