// SPDX-License-Identifier: MIT
/* rproc.c - the servo core's remoteproc instance in sysfs (rproc.h). */
#define _GNU_SOURCE
#include <stdio.h>
#include <string.h>

#include "rproc.h"
#include "sysfs.h"

int rproc_lookup(char *entry, size_t n)
{
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

int rproc_trace_path(char *path, size_t n)
{
	char entry[256];

	if (rproc_lookup(entry, sizeof(entry)))
		return -1;
	snprintf(path, n, "/sys/kernel/debug/remoteproc/%s/trace0", entry);
	return 0;
}
