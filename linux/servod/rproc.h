/* SPDX-License-Identifier: MIT */
/*
 * rproc.h - the servo core's remoteproc instance in sysfs: its state
 * (read, and written: start, stop), its recovery setting, the driver's
 * report_crash attribute (docs/ABI/sysfs-servoamp-remoteproc; servoamp's
 * Zynq-7000 driver only: the upstream xlnx_r5_remoteproc has none, and
 * rproc_has() tells which) and the firmware's trace buffer in debugfs.
 *
 * Which instance: the one the OCM mailbox's devicetree node names
 * (servoamp,remoteproc = <&its node>, devicetree/bindings/sram/
 * servoamp,ocm-mailbox.yaml), found through the phandles under
 * /sys/class/{uio,remoteproc}/.../of_node; without that property, the one
 * named RPROC_NAME. So servod needs no board's name: the Zynq-7000's
 * "servo-cpu1" and the ZynqMP's upstream "ffe00000.r5f" are both found.
 */
#ifndef SERVOD_RPROC_H
#define SERVOD_RPROC_H

#include <stddef.h>

#define RPROC_NAME "servo-cpu1"
#define RPROC_MAILBOX_UIO "ocm-mailbox"	/* the UIO device of amp_lib's region (a name prefix) */

struct rproc {
	char dir[300];		/* /sys/class/remoteproc/remoteprocN, "" until found */
	char state[32];		/* the last state read (rproc_state()) */
	int report_crash;	/* the driver has device/report_crash (supervisor.c looks once per instance) */
};

/* The one lookup: the entry ("remoteprocN") the mailbox names (or named
 * RPROC_NAME). 0 or -1. */
int rproc_lookup(char *entry, size_t n);
/* rp->dir from the lookup: 0, or -1 (not there yet). */
int rproc_find(struct rproc *rp);
/* "offline", "running", "crashed", ... or "absent" (looked up again next time). */
const char *rproc_state(struct rproc *rp);
/* 1 if the instance's directory has attr ("recovery", "device/report_crash"), else 0. */
int rproc_has(const struct rproc *rp, const char *attr);
/* Writes "watchdog" to the driver's report_crash (its path in path): 0 or -1 (errno). */
int rproc_report_crash(const struct rproc *rp, char *path, size_t n);
/* Writes "start" or "stop" to state (the write returns once remoteproc has
 * started or stopped the firmware, or failed to): 0 or -1 (errno). */
int rproc_write_state(const struct rproc *rp, const char *what, char *path, size_t n);
/* Writes "enabled" or "disabled" to recovery (what report_crash makes
 * remoteproc do): 0 or -1 (errno). */
int rproc_write_recovery(const struct rproc *rp, const char *what, char *path, size_t n);
/* Reads recovery into buf ("enabled", "disabled"): 0 or -1 (errno). */
int rproc_read_recovery(const struct rproc *rp, char *buf, size_t bn, char *path, size_t n);
/* The firmware's trace buffer (debugfs trace0): 0, or -1 (no instance yet). */
int rproc_trace_path(char *path, size_t n);

#endif
