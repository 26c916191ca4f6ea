/* SPDX-License-Identifier: MIT */
/*
 * servoamp motion pipeline: G-code to coarse setpoints on the Linux side.
 *
 *   stream/program -> decode -> fit -> look-ahead -> accel -> interp -> setpoints
 *
 * Each arrow is a bounded ring buffer; each stage is a data-dependent task
 * of the library's hybrid data-flow scheduler.  The daemon calls
 * motion_next_setpoint() once per cycle; that call never allocates.
 *
 * Units: millimetres, seconds.  Setpoints are int32 increments
 * (config.increments_per_mm, default 1000: 1 increment = 1 micrometre) and
 * int32 increments per second for the velocity feed-forward.
 */
#ifndef SERVOAMP_MOTION_H
#define SERVOAMP_MOTION_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#ifdef __cplusplus
extern "C" {
#endif

#define MOTION_MAX_AXES 6 /* X Y Z A B C */
#define MOTION_MAX_LINE 256 /* characters per G-code line */

enum motion_errcode {
	MOTION_E_NONE = 0,
	MOTION_E_SYNTAX,      /* malformed text: bad character, unclosed comment */
	MOTION_E_NUMBER,      /* malformed or out-of-range number */
	MOTION_E_UNSUPPORTED, /* unsupported word, G-code or M-code */
	MOTION_E_MODAL,       /* conflicting words in one block */
	MOTION_E_MISSING,     /* a required word is missing (feed, P, I/J/K/R) */
	MOTION_E_ARC,         /* geometrically impossible arc */
	MOTION_E_TRAVEL,      /* target outside the travel limits */
	MOTION_E_LINE_TOO_LONG,
	MOTION_E_CONFIG,      /* invalid configuration */
	MOTION_E_NOMEM,
	MOTION_E_STATE,       /* API used in the wrong state */
	MOTION_E_UNDERRUN,    /* threaded mode: a cycle found no setpoint ready */
};

struct motion_error {
	enum motion_errcode code;
	uint32_t line;   /* 1-based source line, 0 if not tied to a line */
	uint32_t column; /* 1-based column, 0 if not tied to a column */
	char msg[160];
};

const char *motion_errcode_name(enum motion_errcode code);

struct motion_axis_limits {
	double vmax; /* mm/s */
	double amax; /* mm/s^2 */
	double jmax; /* mm/s^3, used when config.jerk_limited */
	double min;  /* travel, mm (machine coordinates) */
	double max;
};

enum motion_policy {
	MOTION_POLICY_HYBRID = 0, /* the hybrid scheduler's rules */
	MOTION_POLICY_FIFO,       /* plain FIFO (round robin) over runnable tasks */
};

enum motion_flow { MOTION_FLOW_XON = 0, MOTION_FLOW_XOFF = 1 };

enum motion_status {
	MOTION_ST_MOVING = 0, /* a planned setpoint */
	MOTION_ST_IDLE,       /* holding position, waiting for more input
			       * (threaded mode: or for the first setpoint of
			       * a motion from rest) */
	MOTION_ST_DONE,       /* program ended (M2/M30 or end of stream) */
	MOTION_ST_FAULT,      /* program error; motion came to rest, holding */
	MOTION_ST_UNDERRUN,   /* threaded mode: no setpoint was ready while the
			       * axes moved (fault) */
};

struct motion_setpoint {
	uint64_t cycle;                /* 0, 1, 2, ... one per call */
	int32_t pos[MOTION_MAX_AXES];  /* increments */
	int32_t vel[MOTION_MAX_AXES];  /* velocity feed-forward, increments/s */
	uint32_t line;                 /* source line being executed */
	uint8_t n_axes;
	uint8_t status;                /* enum motion_status */
};

struct motion;
struct motion_setpoint;

struct motion_config {
	uint32_t n_axes;           /* 1..MOTION_MAX_AXES (default 3) */
	uint32_t period_us;        /* interpolation cycle (default 1000) */
	double increments_per_mm;  /* default 1000.0 */
	struct motion_axis_limits axis[MOTION_MAX_AXES];
	double start_pos[MOTION_MAX_AXES]; /* initial machine position, mm */
	double chord_tol;          /* arc chord-height tolerance, mm (0.001) */
	bool jerk_limited;         /* S-curve profiles (default trapezoid) */
	double junction_share;     /* share of the acceleration (and jerk)
				      budget kept for direction changes at
				      segment junctions, 0 < share < 1 (0.5) */
	uint32_t lookahead;        /* look-ahead window, segments (32) */
	/* streaming input (bytes) */
	uint32_t stream_size;      /* 16384 */
	uint32_t stream_high;      /* XOFF above this level (12288) */
	uint32_t stream_low;       /* XON at or below this level (4096) */
	void (*flow_cb)(void *user, enum motion_flow ev);
	void *flow_user;
	/* queue capacities (items) */
	uint32_t q_blocks, q_segments, q_planned, q_profiles, q_setpoints;
	uint32_t batch;            /* items per task job (8; the look-ahead's
				      and accel's jobs: docs/motion.md) */
	uint32_t min_job;          /* whole jobs: while a neighbour task runs,
				      a task waits for this many items
				      upstream / this much room downstream
				      (0: batch; 1: off, the hybrid scheduler's
				      rule 2 as written); see docs/motion.md */
	enum motion_policy policy;
	/* data-parallel profiles and interpolation: lanes (tasks that solve
	 * profiles, and tasks that interpolate, at the same time, each
	 * 1..MOTION_MAX_WORKERS; 0: MOTION_DEFAULT_LANES) and setpoints per
	 * chunk dealt to an interpolation lane in turn (0: batch; the
	 * profile lanes take batch segments in turn).  The setpoints do not
	 * depend on either; see docs/motion.md. */
	uint32_t interp_lanes;
	uint32_t interp_chunk;
	/* threaded mode: optional periodic "position send" task run by the
	 * worker pool at period_us; it calls motion_next_setpoint() and hands
	 * the result to send_cb. */
	void (*send_cb)(void *user, const struct motion_setpoint *sp);
	void *send_user;
	/* instrumentation: queue-level samples kept (0 = none) and the period
	 * of the monitor task that takes them in threaded mode */
	uint32_t trace_samples;
	uint32_t monitor_period_us;
	/* benchmark only: a sink task drains the setpoint queue */
	bool drain_sink;
};

void motion_config_default(struct motion_config *cfg);

/* Setup (allocates).  Returns 0 or -1 with *err filled. */
int motion_create(const struct motion_config *cfg, struct motion **out,
		  struct motion_error *err);
void motion_destroy(struct motion *m);

/* Input, either a stream (one producer thread) ... */
/* Writes up to len bytes; returns the number accepted (never more than the
 * free space), or -1 once the controller is in a fault state or the stream
 * was ended.  A well-behaved host stops on XOFF and resumes on XON. */
long motion_stream_write(struct motion *m, const char *data, size_t len);
void motion_stream_end(struct motion *m); /* end of program text */
enum motion_flow motion_stream_flow(const struct motion *m);
uint32_t motion_stream_level(const struct motion *m);
/* The stream level that decided the latest XOFF/XON: valid inside the flow
 * callback (the live level may already have moved in threaded mode). */
uint32_t motion_stream_event_level(const struct motion *m);
/* ... or a whole program in memory (not copied; must outlive the run). */
int motion_load_program(struct motion *m, const char *text, size_t len);

/* Threaded mode: a pool of `workers` threads runs the pipeline tasks. */
int motion_start(struct motion *m, unsigned workers);
void motion_stop(struct motion *m);

/* One cycle.  Fills *out with a safe setpoint and returns its status.
 * In synchronous mode (no workers) it runs the pipeline on the calling
 * thread until one setpoint is ready.  Never allocates. */
enum motion_status motion_next_setpoint(struct motion *m,
					 struct motion_setpoint *out);

/* Synchronous mode: run pipeline jobs until nothing is runnable or
 * max_jobs ran; returns the number of jobs run. */
uint32_t motion_pump(struct motion *m, uint32_t max_jobs);

const struct motion_error *motion_last_error(const struct motion *m);
/* Every setpoint of the program has been produced and consumed. */
bool motion_done(const struct motion *m);
/* Threaded mode: block until the run has ended, that is motion_done() or
 * a fault (motion_last_error()), for at most timeout_ms (0: no limit).
 * Returns 0 when it has ended, -1 on timeout or in synchronous mode.
 * The waiting thread sleeps: it takes no CPU time from the workers. */
int motion_wait(struct motion *m, uint32_t timeout_ms);

#define MOTION_N_QUEUES 6   /* stream, blocks, segments, planned, profiles, setpoints */
#define MOTION_MAX_WORKERS 8
/* data tasks: decode, fit, look-ahead, up to MOTION_MAX_WORKERS profile
 * lanes, accel, as many interpolation lanes, sink; plus 2 periodic */
#define MOTION_N_TASKS 24
#define MOTION_DEFAULT_LANES 2

struct motion_stats {
	uint64_t lines, blocks, segments, profiles, setpoints, cycles;
	uint64_t xoff_events, xon_events, underruns, ignored_lines;
	uint32_t peak[MOTION_N_QUEUES];     /* peak occupancy of each queue */
	uint32_t cap[MOTION_N_QUEUES];      /* capacity of each queue */
	uint32_t n_tasks;
	const char *task_name[MOTION_N_TASKS];
	uint64_t runs[MOTION_N_TASKS][MOTION_MAX_WORKERS];
	uint64_t busy_ns[MOTION_N_TASKS];   /* time spent in each task's jobs */
	uint64_t idle[MOTION_MAX_WORKERS];
	unsigned workers;
	/* threaded mode, per worker: time in jobs, asleep, and in the
	 * scheduler path (everything else) */
	uint64_t job_ns[MOTION_MAX_WORKERS];
	uint64_t sleep_ns[MOTION_MAX_WORKERS];
	uint64_t sched_ns[MOTION_MAX_WORKERS];
};
void motion_get_stats(const struct motion *m, struct motion_stats *st);
/* The queues' levels now (the stream in bytes, the others in items) and
 * their capacities, in motion_queue_name() order; from any thread (one
 * atomic read per queue: a snapshot of each, not one consistent cut). */
void motion_queue_levels(const struct motion *m, uint32_t level[MOTION_N_QUEUES],
			 uint32_t cap[MOTION_N_QUEUES]);
const char *motion_queue_name(unsigned q);
/* CSV of queue levels over time: t_us,stream,blocks,segments,... */
int motion_trace_csv(const struct motion *m, FILE *f);

/* An order-sensitive hash of a run's setpoints (line, positions and
 * velocities of the n_axes axes): h = motion_setpoint_hash(h, &sp) over
 * the MOVING setpoints, from h = 0. */
uint64_t motion_setpoint_hash(uint64_t h, const struct motion_setpoint *sp);
/* drain_sink mode: motion_setpoint_hash() of every setpoint the sink
 * consumed, for comparing runs (benchmark and tests). */
uint64_t motion_sink_checksum(const struct motion *m);

#ifdef __cplusplus
}
#endif
#endif
