/* SPDX-License-Identifier: MIT */
/*
 * recovery_rig.h - the rig of servod's recovery tests (recovery_rig.c,
 * test_servod_recovery.c, test_servod_recovery_stop.c): one servod, a
 * servo on a host buffer driven by a ticker thread, remoteproc played in a
 * directory between two passes of servod's main loop.
 */
#ifndef SERVOD_RECOVERY_RIG_H
#define SERVOD_RECOVERY_RIG_H

#include <stdatomic.h>
#include <stdint.h>

#include "check.h"
#include "context.h"

struct rig {
	struct servod *sd;
	char dir[64];			/* the remoteproc instance's directory */
	char pfile[64];			/* servod's parameter file */
	int irq[2];			/* [0] servod's "UIO" fd, [1] the ticker's */
	pthread_t cycle_th, tick_th;
	atomic_int stop_ticker;
	/* the firmware (under fw) */
	pthread_mutex_t fw;
	struct amp_servo s;
	int running, hang, hang_after_attach;
	int attach_retry;		/* started, its attach refused: tried every cycle */
	uint32_t wd_stalls;		/* cycles its watchdog said Linux stalled (AMP_E_STALLED) */
	uint32_t absent;		/* cycles that found the region closed or re-initialised */
	int attach_in_cycle;		/* a start leaves the attach to the next stalled cycle */
	atomic_int attach_due;		/* started: the cycle attaches it */
	atomic_uint attached_in_cycle;
	uint32_t cycles, sets;		/* since its attach */
	uint32_t val[SP_P_COUNT];
	/* remoteproc (test thread) */
	char kstate[16];
	int power, start_fails;
	unsigned starts, stops, reports, kernel_recoveries;
	uint64_t start_ns[16], fail_ns[16];	/* each start, each failed start */
	unsigned fails;
	/* the telemetry client */
	atomic_uint replies, replies_at_stall;
	atomic_int stall_seen;
};

extern struct rig g;
/* the next rig_up plays a driver without device/report_crash whose own
 * recovery is disabled at probe (the upstream xlnx_r5_remoteproc) */
extern int rig_upstream;
extern const char TOKEN[33];	/* the telemetry token when rig_up(..., 1) */

void wfile(const char *dir, const char *name, const char *text);
void rfile(const char *dir, const char *name, char *buf, size_t n);
/* The firmware attaches (a start; refused: tried again every cycle, as
 * rpu_app's link does) / stops (parked: its line left as it is) / hangs. */
void fw_start(void);
void fw_stop(void);
void fw_hang(void);
/* What remoteproc makes of what servod wrote since the last pass. */
void rproc_play(void);
/* One pass of servod's main loop, then remoteproc. */
void pass(void);
uint64_t stat_of(const uint64_t *field);
/* A request as ampctl would send it: the code, msg and the body. */
int req(const char *line, char *msg, size_t mn, char *body, size_t bn);
/* servod up, the firmware started and attached with its parameter set. */
void rig_up(uint32_t limit, uint32_t backoff_ms, int telemetry);
void rig_down(void);
int body_has(const char *body, const char *text);
/* `ampctl fault` says latched=1 (no mailbox request: the servo may hang) */
int latched(void);
/* The rig's own CHECKs passed and failed (check.h counts per file). */
void rig_checks(unsigned *passed, unsigned *failed);

/* check_summary() of the including file with the rig's checks added. */
static inline int rig_summary(const char *name)
{
	unsigned p, f;

	rig_checks(&p, &f);
	check_pass += p;
	check_fail += f;
	return check_summary(name);
}

/* Passes until cond holds or about host_s seconds went by (not an assertion:
 * the case's checks follow). */
#define RUN_UNTIL(cond, host_s)                                                     \
	do {                                                                        \
		uint64_t end_ = mono_now_ns() + (uint64_t)((host_s) * 1e9);         \
		while (!(cond) && (int64_t)(mono_now_ns() - end_) < 0)              \
			pass();                                                     \
	} while (0)

#endif
