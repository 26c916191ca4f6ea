// SPDX-License-Identifier: MIT
/*
 * program_feed.c - the feeder thread of a program run (program.h): the dry
 * run through a second pipeline instance, then the file streamed into the
 * run's pipeline and its setpoints into the setpoint queue.
 */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <sched.h>
#include <stdio.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "servoamp/mono_clock.h"
#include "program.h"
#include "servod.h"

static void motion_cfg(const struct prog_runner *pr, struct motion_config *cfg, const int32_t *start)
{
	const struct prog_opts *o = &pr->opt;

	motion_config_default(cfg);
	cfg->n_axes = PROG_AXES;
	cfg->period_us = o->period_us;
	cfg->increments_per_mm = o->inc_per_mm;
	for (uint32_t k = 0; k < PROG_AXES; k++) {
		cfg->axis[k].vmax = o->vmax;
		cfg->axis[k].amax = o->amax;
		cfg->axis[k].min = -o->travel;
		cfg->axis[k].max = o->travel;
		cfg->start_pos[k] = start ? start[k] / o->inc_per_mm : 0.0;
	}
}

static void pause_2ms(void)
{
	struct timespec ts = { 0, 2000000 };

	nanosleep(&ts, 0);
}

struct sink {
	int to_queue;		/* 0: dry run (count, keep the last) */
	uint64_t n;
	struct motion_setpoint last;
};

/* Writes the file into m while the pipeline says XON (it raises XOFF at
 * stream_high and XON again once drained to stream_low). 1 once the input
 * ended (or the pipeline faulted and takes no more), 0, or -1 (msg). */
static int feed_input(struct prog_runner *pr, struct motion *m, int fd, const char *path, size_t *have,
		      size_t *off, char *msg, size_t msgn)
{
	while (motion_stream_flow(m) == MOTION_FLOW_XON) {
		long w;

		if (*off == *have) {
			ssize_t r = read(fd, pr->feed_buf, sizeof(pr->feed_buf));

			if (r < 0) {
				snprintf(msg, msgn, "%s: read: %s", path, strerror(errno));
				return -1;
			}
			if (r == 0) {
				motion_stream_end(m);
				return 1;
			}
			*have = (size_t)r;
			*off = 0;
		}
		w = motion_stream_write(m, pr->feed_buf + *off, *have - *off);
		if (w < 0)	/* the pipeline faulted: it takes no more input */
			return 1;
		*off += (size_t)w;
		if (w == 0)
			break;
	}
	return 0;
}

/* Streams the file into m with the pipeline's flow control and takes its
 * setpoints until DONE / FAULT. Returns the final status, or -1 (aborted
 * or I/O error: msg). */
static int stream_program(struct prog_runner *pr, struct motion *m, const char *path, struct sink *k, char *msg,
			  size_t msgn)
{
	size_t have = 0, off = 0;
	int fd = open(path, O_RDONLY | O_CLOEXEC), ended = 0;
	uint32_t batches = 0;

	if (fd < 0) {
		snprintf(msg, msgn, "%s: %s", path, strerror(errno));
		return -1;
	}
	for (;;) {
		uint32_t room;

		if (atomic_load(&pr->feeder_abort)) {
			close(fd);
			snprintf(msg, msgn, "aborted");
			return -1;
		}
		if (!ended) {
			int rc = feed_input(pr, m, fd, path, &have, &off, msg, msgn);

			if (rc < 0) {
				close(fd);
				return -1;
			}
			ended = rc;
		}
		/* output */
		room = k->to_queue ? ring_room(&pr->queue) : 512u;
		if (!room) {
			pause_2ms();
			continue;
		}
		while (room--) {
			struct motion_setpoint sp;
			enum motion_status st = motion_next_setpoint(m, &sp);

			if (k->to_queue)
				ring_push(&pr->queue, &sp);
			k->last = sp;
			k->n++;
			if (st == MOTION_ST_DONE || st == MOTION_ST_FAULT || st == MOTION_ST_UNDERRUN) {
				close(fd);
				return st;
			}
			if (!ended && motion_stream_flow(m) == MOTION_FLOW_XON)
				break;	/* drained to the low watermark: refill first */
		}
		if (k->to_queue && (++batches & 7u) == 0) {
			pthread_mutex_lock(&pr->info_lock);
			motion_get_stats(m, &pr->info.ms);
			pthread_mutex_unlock(&pr->info_lock);
		}
	}
}

static void fmt_error(const struct motion_error *e, const char *path, char *buf, size_t n)
{
	if (!e)
		snprintf(buf, n, "%s: error: unknown", path);
	else if (e->line)
		snprintf(buf, n, "%s:%u:%u: error: %s (%s)", path, e->line, e->column, e->msg,
			 motion_errcode_name(e->code));
	else
		snprintf(buf, n, "%s: error: %s (%s)", path, e->msg, motion_errcode_name(e->code));
}

/* 1. The dry run: the whole program through a second pipeline instance,
 * synchronous, nothing sent to the servo. 0 (checked), or -1 (msg). */
static int dry_run(struct prog_runner *pr, const struct motion_config *cfg, uint64_t t0, char *msg, size_t n)
{
	struct motion_error err;
	struct motion *m = 0;
	struct sink k;
	int st;

	if (motion_create(cfg, &m, &err)) {
		fmt_error(&err, "config", msg, n);
		return -1;
	}
	memset(&k, 0, sizeof(k));
	st = stream_program(pr, m, pr->info.path, &k, msg, n);
	if (st == MOTION_ST_FAULT || st == MOTION_ST_UNDERRUN)
		fmt_error(motion_last_error(m), pr->info.path, msg, n);
	motion_destroy(m);
	if (st != MOTION_ST_DONE)
		return -1;
	pthread_mutex_lock(&pr->info_lock);
	pr->info.dry_setpoints = k.n;
	for (uint32_t i = 0; i < PROG_AXES; i++)
		pr->info.end_inc[i] = k.last.pos[i];
	pr->info.t_check_s = (double)(mono_now_ns() - t0) * 1e-9;
	pr->info.verdict = 1;
	pthread_mutex_unlock(&pr->info_lock);
	return 0;
}

/* The cycle thread ends the run on a FAULT setpoint at the last position. */
static void push_fault_marker(struct prog_runner *pr, struct sink *k)
{
	while (ring_room(&pr->queue) == 0 && !atomic_load(&pr->feeder_abort))
		pause_2ms();
	if (atomic_load(&pr->feeder_abort))
		return;
	k->last.status = MOTION_ST_FAULT;
	memset(k->last.vel, 0, sizeof(k->last.vel));
	if (!k->n)
		for (uint32_t i = 0; i < PROG_AXES; i++)
			k->last.pos[i] = pr->run_start[i];
	ring_push(&pr->queue, &k->last);
}

/* 2. The run: the cycle thread is ARMED and pops the queue. */
static void real_run(struct prog_runner *pr, const struct motion_config *cfg)
{
	struct motion_error err;
	struct motion *m = 0;
	struct sink k;
	char msg[512] = "";
	int st;

	memset(&k, 0, sizeof(k));
	if (motion_create(cfg, &m, &err)) {
		fmt_error(&err, "config", msg, sizeof(msg));
		pthread_mutex_lock(&pr->info_lock);
		snprintf(pr->info.error, sizeof(pr->info.error), "%s", msg);
		pthread_mutex_unlock(&pr->info_lock);
		push_fault_marker(pr, &k);
		return;
	}
	k.to_queue = 1;
	st = stream_program(pr, m, pr->info.path, &k, msg, sizeof(msg));
	pthread_mutex_lock(&pr->info_lock);
	motion_get_stats(m, &pr->info.ms);
	if (st == MOTION_ST_FAULT || st == MOTION_ST_UNDERRUN)
		fmt_error(motion_last_error(m), pr->info.path, pr->info.error, sizeof(pr->info.error));
	else if (st < 0 && !atomic_load(&pr->feeder_abort))
		snprintf(pr->info.error, sizeof(pr->info.error), "%s", msg);
	pthread_mutex_unlock(&pr->info_lock);
	motion_destroy(m);
	if (st < 0 && !atomic_load(&pr->feeder_abort))
		push_fault_marker(pr, &k);
}

static void *feeder_main(void *arg)
{
	struct prog_runner *pr = arg;
	struct motion_config cfg;
	char msg[512] = "";
	uint64_t t0 = mono_now_ns();

	motion_cfg(pr, &cfg, pr->run_start);
	if (dry_run(pr, &cfg, t0, msg, sizeof(msg))) {
		pthread_mutex_lock(&pr->info_lock);
		snprintf(pr->info.error, sizeof(pr->info.error), "%s", msg);
		pr->info.verdict = 2;
		pr->info.t_check_s = (double)(mono_now_ns() - t0) * 1e-9;
		pthread_mutex_unlock(&pr->info_lock);
		pthread_mutex_lock(pr->cycle_lock);
		if (atomic_load(&pr->mode) == PM_ARMED)
			prog_end_run(pr, PR_REFUSED);
		pthread_mutex_unlock(pr->cycle_lock);
	} else {
		int want = PR_CHECKING;

		atomic_compare_exchange_strong(&pr->result, &want, PR_RUNNING);
		real_run(pr, &cfg);
	}
	atomic_store(&pr->feeder_done, 1);
	return 0;
}

int prog_feeder_start(struct prog_runner *pr)
{
	pthread_attr_t attr;
	int rc;

	pthread_attr_init(&attr);
	pthread_attr_setinheritsched(&attr, PTHREAD_EXPLICIT_SCHED);
	pthread_attr_setschedpolicy(&attr, SCHED_OTHER);
	rc = pthread_create(&pr->feeder_th, &attr, feeder_main, pr);
	pthread_attr_destroy(&attr);
	return rc;
}
