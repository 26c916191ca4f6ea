/* SPDX-License-Identifier: MIT */
/*
 * The hybrid real-time scheduler (internal to libmotion): it runs the
 * pipeline's stages as tasks, in threaded mode on a pool of workers.
 *
 * Periodic tasks are (P, T): priority (0 = highest) and period.  Data-
 * dependent tasks are (O, UL, DL): position in the chain, items buffered
 * upstream, items buffered downstream.  A ready periodic task always wins
 * (highest priority first); otherwise the data task chosen by
 *   (1) not if it is already running on a core,
 *   (2) only if its upstream has data and its downstream has room,
 *   (3) largest UL - DL first,
 *   (4) on ties, the most upstream (smallest O) first;
 * otherwise idle.  sched_decide() is that rule as a pure function.
 *
 * The pool runs one worker thread per core; every decision is taken under
 * one mutex, jobs run outside it.
 */
#ifndef SERVOAMP_MOTION_SCHEDULER_H
#define SERVOAMP_MOTION_SCHEDULER_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include "motion/motion.h"

#define SCHED_MAX_TASKS MOTION_N_TASKS
#define SCHED_MAX_WORKERS MOTION_MAX_WORKERS
#define SCHED_MAX_LEVELS 16

struct sched_pstate {
	uint8_t prio;
	bool ready;   /* release time reached */
	bool running;
};

struct sched_dstate {
	uint8_t order;   /* O: position in the chain, smaller = upstream */
	uint32_t ul;     /* UL: items available upstream */
	uint32_t dl;     /* DL: items buffered downstream */
	uint32_t dcap;   /* capacity of the downstream queue */
	bool running;
	uint64_t last;   /* dispatch sequence of its last run (FIFO policy) */
};

enum sched_kind { SCHED_CHOICE_IDLE = 0, SCHED_CHOICE_PERIODIC, SCHED_CHOICE_DATA };

struct sched_choice {
	enum sched_kind kind;
	int index; /* into the periodic or the data array; -1 when idle */
};

/* Pure: no side effects, depends on its arguments only. */
struct sched_choice sched_decide(enum motion_policy policy,
				 const struct sched_pstate *p, size_t np,
				 const struct sched_dstate *d, size_t nd);

/* Whole jobs, a refinement of rule 2 (pure, applied to the snapshot before
 * sched_decide()).  While a task's upstream neighbour (a task at the next
 * smaller O: one of the lanes when that stage has several) is running,
 * "its upstream queue has data" means at least min_job items; while a
 * downstream neighbour is running, "its downstream queue has room" means
 * room for at least min_job items.  Otherwise rule 2 is
 * unchanged, so with no task running (one worker) it changes nothing, and
 * a task it holds back always has a running neighbour that will end its
 * job and let it go.  Without it, a worker left with little to do keeps
 * taking a few items right behind (or ahead of) the task running on the
 * other core, and those micro-jobs cost more than they do (see
 * docs/motion.md).  min_job <= 1 is rule 2 as written. */
void sched_gate(struct sched_dstate *d, size_t nd, uint32_t min_job);

/* A job processes a bounded amount of work; returns the items it handled. */
typedef uint32_t (*sched_job_fn)(void *arg, unsigned worker);
typedef void (*sched_levels_fn)(void *arg, uint32_t *ul, uint32_t *dl,
				uint32_t *dcap);
typedef void (*sched_sample_fn)(void *arg, uint32_t *levels);

struct sched_task_desc {
	const char *name;
	bool periodic;
	uint8_t prio;        /* periodic */
	uint32_t period_us;  /* periodic */
	uint8_t order;       /* data */
	sched_levels_fn levels; /* data */
	sched_job_fn run;
	void *arg;
};

struct sched;

struct sched *sched_create(enum motion_policy policy,
			   const struct sched_task_desc *tasks, size_t n,
			   uint32_t trace_samples);
void sched_destroy(struct sched *s);
/* Whole jobs (see sched_gate()); 0 or 1: off (the default). */
void sched_set_min_job(struct sched *s, uint32_t min_job);

/* Queue-level sampler for the trace (levels of n queues). */
void sched_set_sampler(struct sched *s, unsigned n, const char *const *names,
		       sched_sample_fn fn, void *arg);
void sched_sample(struct sched *s); /* record one sample now */
int sched_trace_csv(const struct sched *s, FILE *f);

/* Synchronous mode: decide and run one job on the calling thread. */
struct sched_choice sched_step(struct sched *s);

/* Threaded mode. */
int sched_start(struct sched *s, unsigned workers);
void sched_stop(struct sched *s);
void sched_kick(struct sched *s); /* input changed outside the pool */

struct sched_stats {
	size_t n_tasks;
	unsigned workers;
	const char *name[SCHED_MAX_TASKS];
	uint64_t runs[SCHED_MAX_TASKS][SCHED_MAX_WORKERS];
	uint64_t items[SCHED_MAX_TASKS];
	uint64_t overruns[SCHED_MAX_TASKS];
	uint64_t busy_ns[SCHED_MAX_TASKS]; /* time spent in jobs */
	uint64_t idle[SCHED_MAX_WORKERS];
	uint64_t decisions;
	/* per worker, threaded mode: time in jobs, time asleep (nothing
	 * runnable), and the rest of the worker's life: the scheduler path
	 * (lock, levels, decision, bookkeeping, wake-ups) */
	uint64_t job_ns[SCHED_MAX_WORKERS];
	uint64_t sleep_ns[SCHED_MAX_WORKERS];
	uint64_t sched_ns[SCHED_MAX_WORKERS];
};
void sched_get_stats(struct sched *s, struct sched_stats *st);

#endif
