// SPDX-License-Identifier: MIT
/* rproc.c - the servo core's remoteproc instance in sysfs (rproc.h). */
#define _GNU_SOURCE
#include <dirent.h>
#include <stdio.h>
#include <string.h>

#include "rproc.h"
#include "sysfs.h"

int rproc_lookup(char *entry, size_t n)
{
	DIR *d = opendir("/sys/class/remoteproc");
	struct dirent *e;
	char path[600], buf[64];
	int rc = -1;

	if (!d)
		return -1;
	while ((e = readdir(d))) {
		if (strncmp(e->d_name, "remoteproc", 10))
			continue;
		snprintf(path, sizeof(path), "/sys/class/remoteproc/%s/name", e->d_name);
		if (!sysfs_read(path, buf, sizeof(buf)) && !strcmp(buf, RPROC_NAME)) {
			snprintf(entry, n, "%s", e->d_name);
			rc = 0;
			break;
		}
	}
	closedir(d);
	return rc;
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

int rproc_trace_path(char *path, size_t n)
{
	char entry[256];

	if (rproc_lookup(entry, sizeof(entry)))
		return -1;
	snprintf(path, n, "/sys/kernel/debug/remoteproc/%s/trace0", entry);
	return 0;
}
