// SPDX-License-Identifier: MIT
/*
 * program_feed.c - the feeder thread of a program run (program.h): the
 * program read once into memory from the file prog_run() opened and
 * checked, the dry run of that text through a second pipeline instance
 * (bounded: at most opt.max_s seconds of motion), then the same text
 * streamed into the run's pipeline and its setpoints into the setpoint
 * queue.
 */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <sched.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
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
	uint64_t limit;		/* dry run: most setpoints taken (opt.max_s) */
	struct motion_setpoint last;
};

/* Reads the program from pr->prog_fd (a regular file prog_run opened and
 * checked) into pr->text, at most PROG_MAX_BYTES, and closes the file.
 * 0, or -1 (msg). */
static int load_program(struct prog_runner *pr, const char *path, char *msg, size_t msgn)
{
	int fd = pr->prog_fd;
	struct stat st;
	size_t cap, len = 0;
	char *buf;

	pr->prog_fd = -1;
	cap = (fstat(fd, &st) == 0 && st.st_size > 0 ? (size_t)st.st_size : 0) + 4096u;
	if (cap > PROG_MAX_BYTES + 1u)
		cap = PROG_MAX_BYTES + 1u;
	buf = malloc(cap);
	while (buf) {
		ssize_t r = read(fd, buf + len, cap - len);

		if (r < 0 && errno == EINTR)
			continue;
		if (r < 0) {
			snprintf(msg, msgn, "%s: read: %s", path, strerror(errno));
			break;
		}
		if (r == 0) {
			close(fd);
			pr->text = buf;
			pr->text_len = len;
			return 0;
		}
		len += (size_t)r;
		if (len > PROG_MAX_BYTES) {
			snprintf(msg, msgn, "%s: more than the %u bytes servod takes", path, PROG_MAX_BYTES);
			break;
		}
		if (len == cap) {	/* the file grew while read */
			char *nb = realloc(buf, cap + 65536u);

			if (!nb)
				break;
			buf = nb;
			cap += 65536u;
		}
	}
	if (!buf || !msg[0])
		snprintf(msg, msgn, "%s: out of memory", path);
	free(buf);
	close(fd);
	return -1;
}

/* Writes the program text into m while the pipeline says XON (it raises
 * XOFF at stream_high and XON again once drained to stream_low). 1 once
 * the text ended (or the pipeline faulted and takes no more), else 0. */
static int feed_input(struct prog_runner *pr, struct motion *m, size_t *off)
{
	while (motion_stream_flow(m) == MOTION_FLOW_XON) {
		long w;

		if (*off == pr->text_len) {
			motion_stream_end(m);
			return 1;
		}
		w = motion_stream_write(m, pr->text + *off, pr->text_len - *off);
		if (w < 0)	/* the pipeline faulted: it takes no more input */
			return 1;
		*off += (size_t)w;
		if (w == 0)
			break;
	}
	return 0;
}

/* Streams the program into m with the pipeline's flow control and takes
 * its setpoints until DONE / FAULT. Returns the final status, or -1
 * (aborted, or the dry run's bound reached: msg). */
static int stream_program(struct prog_runner *pr, struct motion *m, const char *path, struct sink *k, char *msg,
			  size_t msgn)
{
	size_t off = 0;
	int ended = 0;
	uint32_t batches = 0;
	uint64_t queues_ns = 0;

	for (;;) {
		uint32_t room;

		if (k->to_queue && pr->on_queues && mono_now_ns() - queues_ns >= PROG_QUEUES_NS) {
			uint32_t level[MOTION_N_QUEUES], cap[MOTION_N_QUEUES];

			queues_ns = mono_now_ns();
			motion_queue_levels(m, level, cap);
			pr->on_queues(pr->on_queues_user, level, cap, MOTION_N_QUEUES);
		}

		if (atomic_load(&pr->feeder_abort)) {
			snprintf(msg, msgn, "aborted");
			return -1;
		}
		if (!ended)
			ended = feed_input(pr, m, &off);
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
			if (st == MOTION_ST_DONE || st == MOTION_ST_FAULT || st == MOTION_ST_UNDERRUN)
				return st;
			if (!k->to_queue && k->n > k->limit) {
				snprintf(msg, msgn, "%s:%u: error: the program runs longer than %u s "
					 "(servod --max-program-s): a long dwell (G4 P) or a very low feed (F)?",
					 path, sp.line, pr->opt.max_s);
				return -1;
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
	k.limit = (uint64_t)pr->opt.max_s * 1000000u / (cfg->period_us ? cfg->period_us : 1u);
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
	if (load_program(pr, pr->info.path, msg, sizeof(msg)) || dry_run(pr, &cfg, t0, msg, sizeof(msg))) {
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
	free(pr->text);
	pr->text = 0;
	pr->text_len = 0;
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
