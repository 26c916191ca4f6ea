/* SPDX-License-Identifier: MIT */
/*
 * program.h - servod's G-code runner: the motion pipeline (motion/, public
 * API motion/motion.h only) drives the servo axes, and the path error of the
 * run is measured from the feedback (docs/cycle.md, "servod: G-code
 * programs"; path_error.h).
 *
 * Threads:
 *  - the control thread (servod's main thread: ampctl requests) starts and
 *    stops runs: prog_run(), prog_stop(), prog_verdict();
 *  - one feeder thread per run (normal priority, program_feed.c) reads the
 *    program once into memory from the file prog_run() opened and checked
 *    (a regular file of at most PROG_MAX_BYTES), checks the whole program
 *    with a dry run through a second pipeline instance (at most
 *    opt.max_s seconds of motion), then streams the same text into the
 *    pipeline with its XOFF/XON watermark flow
 *    control and calls motion_next_setpoint() ahead of time into a
 *    lock-free SPSC queue of setpoints (queue: motion/ring.h, in the
 *    runner's own storage);
 *  - the cycle thread (SCHED_FIFO) only pops that queue: prog_cycle() and
 *    prog_feedback() never block, never allocate, never make a syscall.
 *    An empty queue while a program runs is an underrun: the axes hold the
 *    last setpoint for that cycle and it is counted.
 *
 * Modes of the cycle thread (mode):
 *   SINE      servod's idle sine (before the first run, unless --idle hold)
 *   HOLD      hold hold_pos[] (after a run, a stop, a refused program)
 *   ARMED     hold, until the axes settled (SETTLE_CYCLES) and the queue is
 *             primed (PREFILL setpoints or the whole program), then RUN
 *   RUN       one setpoint popped per cycle
 *   STOPPING  `ampctl stop`: the program's own path, time-scaled by a speed
 *             factor that ramps 1 -> 0 at opt.amax, then HOLD
 */
#ifndef SERVOD_PROGRAM_H
#define SERVOD_PROGRAM_H

#include <pthread.h>
#include <stdatomic.h>
#include <stddef.h>
#include <stdint.h>

#include "amp/amp.h"
#include "motion/motion.h"
#include "path_error.h"
#include "motion/ring.h"

#define PROG_AXES 3u		/* X Y Z drive servo axes 0 1 2 */
#define PROG_QUEUE_N 1024u	/* setpoints buffered ahead (1.02 s at 1 ms), a power of two */
#define PROG_MAX_BYTES (16u << 20)	/* largest program file servod takes */
#define PROG_MAX_S_DEFAULT 3600u	/* longest program (its dry run's setpoints), s */

struct out;

struct prog_opts {
	double inc_per_mm;	/* servo increments per program millimetre (1000) */
	double vmax;		/* per-axis velocity limit of the planner, mm/s (200) */
	double amax;		/* per-axis acceleration limit, mm/s^2 (2000); also the stop ramp */
	double travel;		/* travel limit, +-mm around 0 (500) */
	uint32_t period_us;	/* cycle period (the pipeline's interpolation period) */
	int idle_hold;		/* 0: servod's sine until the first run; 1: hold from the start */
	uint32_t max_s;		/* longest program, s (--max-program-s): the dry run stops there */
};

enum prog_mode { PM_SINE, PM_HOLD, PM_ARMED, PM_RUN, PM_STOPPING };
enum prog_result { PR_NONE, PR_CHECKING, PR_RUNNING, PR_DONE, PR_STOPPED, PR_FAULT, PR_REFUSED };

/* What the cycle thread does with the program (under the cycle lock). */
struct prog_playback {
	int32_t hold_pos[AMP_MAX_AXES];
	int have_hold;
	int resync;			/* the next feedback sets hold_pos (start, servo restarted) */
	uint32_t armed_cycles;
	struct motion_setpoint cur;	/* last setpoint sent in RUN / STOPPING */
	double stop_s, stop_ds, stop_f;	/* stop: speed factor, its step, fraction cur -> next */
	uint32_t line;			/* source line of the last setpoint */
	uint64_t prog_cycles, underruns, setpoints_used;
	struct path_error pe;
};

/* The run as the control and feeder threads know it (under info_lock). */
struct prog_info {
	char path[256];
	char error[512];
	int verdict;			/* 0 checking, 1 ok, 2 refused */
	struct motion_stats ms;		/* of the running pipeline (feeder's snapshot) */
	uint64_t dry_setpoints;
	int32_t end_inc[PROG_AXES];	/* program end point (dry run), increments */
	double t_check_s;
	uint64_t runs;
};

struct prog_runner {
	struct prog_opts opt;
	pthread_mutex_t *cycle_lock;	/* held by the cycle thread around prog_cycle/prog_feedback */
	_Atomic int mode;		/* enum prog_mode */
	_Atomic int result;		/* enum prog_result */
	atomic_int req_hold, req_stop, feeder_done, feeder_abort;
	atomic_int link_lost;		/* why a run ended: 1 link lost, 2 safe stop, 3 servo fault, 4 drive fault */
	atomic_int drive_fault;		/* link_lost 4: axis << 16 | the drive's error code */
	struct prog_playback play;
	struct ring queue;		/* struct motion_setpoint: feeder -> cycle thread */
	_Alignas(RING_CACHELINE) unsigned char queue_buf[RING_BUF_BYTES(sizeof(struct motion_setpoint), PROG_QUEUE_N)];
	pthread_mutex_t info_lock;
	struct prog_info info;
	/* the feeder thread */
	pthread_t feeder_th;
	int feeder_alive;
	int prog_fd;			/* opened and checked by prog_run, read and closed by the feeder */
	char *text;			/* the program, read once: dry run and run use the same text */
	size_t text_len;
	int32_t run_start[AMP_MAX_AXES];
	/* while a program runs, about every PROG_QUEUES_NS: the pipeline's
	 * queue levels (servod: telemetry QUEUES); NULL: not wanted */
	void (*on_queues)(void *user, const uint32_t *level, const uint32_t *cap, unsigned n);
	void *on_queues_user;
};

#define PROG_QUEUES_NS 100000000ull	/* 10 queue-level samples a second */

/* Before the cycle thread starts. cycle_lock: servod's sd->lock. */
void prog_init(struct prog_runner *pr, const struct prog_opts *o, pthread_mutex_t *cycle_lock);

/* ---- cycle thread (under the cycle lock) ------------------------------------ */
/* 1 while the runner drives the axes (or takes them over this cycle). */
int prog_driving(struct prog_runner *pr);
/* 1 before the first run: cmd[] holds the sine, where the hold starts. */
int prog_on_sine(struct prog_runner *pr);
/* Overrides cmd[0..n) unless the mode is SINE (hold, program, stop ramp).
 * seq: the command sequence amp_linux_cycle() is about to publish. */
void prog_cycle(struct prog_runner *pr, struct amp_cmd_axis *cmd, uint32_t n, uint32_t seq);
/* After amp_linux_cycle(): rc its result, fresh = a new feedback record. */
void prog_feedback(struct prog_runner *pr, int rc, const struct amp_fb_record *fb, uint32_t n, int fresh);
/* Ends the run with result res (and the queue's producer). */
void prog_end_run(struct prog_runner *pr, int res);

/* ---- control thread ------------------------------------------------------------ */
/* Starts a run (0) or fails (SE_* code, message in msg). Never waits on
 * the file: it must be a regular file (stat, then opened O_NONBLOCK and
 * checked again with fstat) of at most PROG_MAX_BYTES. */
int prog_run(struct prog_runner *pr, const char *path, uint32_t period_us, char *msg, size_t n);
/* 1 when the dry run finished (verdict in msg: "ok ..." or the error), 0 while it runs. */
int prog_verdict(struct prog_runner *pr, int *refused, char *msg, size_t n);
int prog_stop(struct prog_runner *pr, char *msg, size_t n);

/* State and figures as "key=value" lines (a snapshot taken under the
 * cycle lock); cmd/act: the last commanded and actual positions. */
void prog_format_status(struct prog_runner *pr, struct out *o, const int32_t *cmd, const int32_t *act);
void prog_format_stats(struct prog_runner *pr, struct out *o);

/* ---- feeder thread (program_feed.c) ----------------------------------------------- */
/* Starts the feeder of the run armed by prog_run: 0 or an errno. */
int prog_feeder_start(struct prog_runner *pr);

#endif
