/* SPDX-License-Identifier: MIT */
/*
 * program.h - servod's G-code runner: the motion pipeline (motion/, public
 * API motion/motion.h only) drives the servo axes, and the path error of the
 * run is measured from the feedback (docs/cycle.md, "servod: G-code
 * programs").
 *
 * Threads:
 *  - the control thread (servod's main thread: ampctl requests) starts and
 *    stops runs: prog_run(), prog_stop(), prog_verdict();
 *  - one feeder thread per run (normal priority) checks the whole program
 *    with a dry run through a second pipeline instance, then streams the
 *    file into the pipeline with its XOFF/XON watermark flow control and
 *    calls motion_next_setpoint() ahead of time into a lock-free SPSC ring
 *    of setpoints;
 *  - the cycle thread (SCHED_FIFO) only pops that ring: prog_cycle() and
 *    prog_feedback() never block, never allocate, never make a syscall.
 *    An empty ring while a program runs is an underrun: the axes hold the
 *    last setpoint for that cycle and it is counted.
 */
#ifndef SERVOD_PROGRAM_H
#define SERVOD_PROGRAM_H

#include <pthread.h>
#include <stddef.h>
#include <stdint.h>

#include "amp/amp.h"

struct prog_opts {
	double inc_per_mm;	/* servo increments per program millimetre (1000) */
	double vmax;		/* per-axis velocity limit of the planner, mm/s (200) */
	double amax;		/* per-axis acceleration limit, mm/s^2 (2000); also the stop ramp */
	double travel;		/* travel limit, +-mm around 0 (500) */
	uint32_t period_us;	/* cycle period (the pipeline's interpolation period) */
	int idle_hold;		/* 0: servod's sine until the first run; 1: hold from the start */
};

/* Before the cycle thread starts. cycle_lock: the lock the cycle thread
 * holds around prog_cycle()/prog_feedback() (servod's amp_lock). */
void prog_init(const struct prog_opts *o, pthread_mutex_t *cycle_lock);

/* ---- cycle thread (under amp_lock) ---------------------------------------- */
/* cmd[0..n) holds the idle sine; overrides it unless the mode is SINE.
 * seq: the command sequence amp_linux_cycle() is about to publish. */
void prog_cycle(struct amp_cmd_axis *cmd, uint32_t n, uint32_t seq);
/* After amp_linux_cycle(): rc its result, fresh = a new feedback record. */
void prog_feedback(int rc, const struct amp_fb_record *fb, uint32_t n, int fresh);

/* ---- control thread ----------------------------------------------------------- */
/* Starts a run (0) or fails (SE_* code, message in msg). */
int prog_run(const char *path, uint32_t period_us, char *msg, size_t n);
/* 1 when the dry run finished (verdict in msg: "ok ..." or the error), 0 while it runs. */
int prog_verdict(int *refused, char *msg, size_t n);
int prog_stop(char *msg, size_t n);

/* State and figures as "key=value" lines (a snapshot taken under cycle_lock). */
void prog_format_status(char *buf, size_t n);
void prog_format_stats(char *buf, size_t n);

#endif
