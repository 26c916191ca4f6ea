/* SPDX-License-Identifier: MIT */
/*
 * motion_cli: run a G-code program through the pipeline and print the
 * setpoints.  The file is streamed through the XOFF/XON flow control like a
 * host would send it.
 *
 *   motion_cli [options] FILE|-
 *     --csv FILE       setpoints as CSV ('-' = stdout)
 *     --trace FILE     queue levels over time as CSV
 *     --workers N      threaded mode: N worker threads, real-time send task
 *     --policy P       hybrid (default) or fifo
 *     --period-us N    cycle period (1000)
 *     --scale S        increments per mm (1000)
 *     --vmax V --amax A --jmax J   limits of every axis (mm/s, mm/s^2, mm/s^3)
 *     --travel L       travel limits +-L mm on every axis (1000)
 *     --jerk           jerk-limited (S-curve) profiles
 *     --tol MM         arc chord tolerance (0.001)
 *     --axes N         number of axes (3)
 *     --chunk N        bytes per stream write (4096)
 *     --max-cycles N   stop after N cycles
 *     --quiet          no summary
 */
#define _POSIX_C_SOURCE 200809L
#include <errno.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "motion/motion.h"

struct out {
	FILE *csv;
	unsigned n_axes;
	atomic_int status;
	atomic_ullong count;
};

static void write_sp(struct out *o, const struct motion_setpoint *sp)
{
	if (!o->csv)
		return;
	fprintf(o->csv, "%llu,%u,%u", (unsigned long long)sp->cycle, sp->status, sp->line);
	for (unsigned k = 0; k < o->n_axes; k++)
		fprintf(o->csv, ",%d", sp->pos[k]);
	for (unsigned k = 0; k < o->n_axes; k++)
		fprintf(o->csv, ",%d", sp->vel[k]);
	fputc('\n', o->csv);
}

static void send_cb(void *user, const struct motion_setpoint *sp)
{
	struct out *o = user;

	write_sp(o, sp);
	atomic_store(&o->status, sp->status);
	atomic_fetch_add(&o->count, 1);
}

static void usage(void)
{
	fprintf(stderr, "usage: motion_cli [--csv F] [--trace F] [--workers N] [--policy hybrid|fifo]\n"
			"                  [--period-us N] [--scale S] [--vmax V] [--amax A] [--jmax J]\n"
			"                  [--travel L] [--jerk] [--tol MM] [--axes N] [--chunk N]\n"
			"                  [--max-cycles N] [--quiet] FILE|-\n");
}

static void sleep_us(long us)
{
	struct timespec ts = { us / 1000000, (us % 1000000) * 1000 };
	nanosleep(&ts, NULL);
}

/* Everything the command line sets, with the defaults of motion_config. */
struct cli {
	struct motion_config cfg;
	const char *path, *csv, *trace;
	unsigned workers;
	size_t chunk;
	unsigned long long max_cycles;
	bool quiet;
};

/* A number or a clear error: atoi() would take "12abc" or "" as a value. */
static int parse_num(const char *opt, const char *v, double lo, double hi, double *out)
{
	char *end;
	double d;

	errno = 0;
	d = strtod(v, &end);
	if (errno || end == v || *end || !(d >= lo && d <= hi)) {
		fprintf(stderr, "motion_cli: %s: '%s' is not a number in [%g, %g]\n", opt, v, lo, hi);
		return -1;
	}
	*out = d;
	return 0;
}

static void set_all_axes(struct motion_config *cfg, const char *opt, double d)
{
	for (int k = 0; k < MOTION_MAX_AXES; k++) {
		struct motion_axis_limits *ax = &cfg->axis[k];

		if (strcmp(opt, "--vmax") == 0)
			ax->vmax = d;
		else if (strcmp(opt, "--amax") == 0)
			ax->amax = d;
		else if (strcmp(opt, "--jmax") == 0)
			ax->jmax = d;
		else {
			ax->min = -d;
			ax->max = d;
		}
	}
}

/* One option with a value; returns 0, or -1 after printing why. */
static int set_option(struct cli *c, const char *a, const char *v)
{
	double d = 0;

	if (strcmp(a, "--csv") == 0) {
		c->csv = v;
	} else if (strcmp(a, "--trace") == 0) {
		c->trace = v;
	} else if (strcmp(a, "--policy") == 0) {
		if (strcmp(v, "fifo") && strcmp(v, "hybrid")) {
			fprintf(stderr, "motion_cli: --policy: '%s' is neither hybrid nor fifo\n", v);
			return -1;
		}
		c->cfg.policy = strcmp(v, "fifo") == 0 ? MOTION_POLICY_FIFO : MOTION_POLICY_HYBRID;
	} else if (strcmp(a, "--workers") == 0) {
		if (parse_num(a, v, 0, 64, &d))
			return -1;
		c->workers = (unsigned)d;
	} else if (strcmp(a, "--period-us") == 0) {
		if (parse_num(a, v, 1, 1e6, &d))
			return -1;
		c->cfg.period_us = (uint32_t)d;
	} else if (strcmp(a, "--axes") == 0) {
		if (parse_num(a, v, 1, MOTION_MAX_AXES, &d))
			return -1;
		c->cfg.n_axes = (uint32_t)d;
	} else if (strcmp(a, "--chunk") == 0) {
		if (parse_num(a, v, 1, 1 << 24, &d))
			return -1;
		c->chunk = (size_t)d;
	} else if (strcmp(a, "--max-cycles") == 0) {
		if (parse_num(a, v, 0, 1e15, &d))
			return -1;
		c->max_cycles = (unsigned long long)d;
	} else if (strcmp(a, "--scale") == 0) {
		if (parse_num(a, v, 0, 1e12, &d))
			return -1;
		c->cfg.increments_per_mm = d;
	} else if (strcmp(a, "--tol") == 0) {
		if (parse_num(a, v, 0, 1e12, &d))
			return -1;
		c->cfg.chord_tol = d;
	} else if (strcmp(a, "--vmax") == 0 || strcmp(a, "--amax") == 0 ||
		   strcmp(a, "--jmax") == 0 || strcmp(a, "--travel") == 0) {
		if (parse_num(a, v, 0, 1e12, &d))
			return -1;
		set_all_axes(&c->cfg, a, d);
	} else {
		usage();
		return -1;
	}
	return 0;
}

static int parse_args(struct cli *c, int argc, char **argv)
{
	memset(c, 0, sizeof(*c));
	motion_config_default(&c->cfg);
	c->chunk = 4096;
	for (int i = 1; i < argc; i++) {
		const char *a = argv[i];

		if (strcmp(a, "--jerk") == 0) {
			c->cfg.jerk_limited = true;
		} else if (strcmp(a, "--quiet") == 0) {
			c->quiet = true;
		} else if (a[0] == '-' && a[1]) {
			if (i + 1 >= argc) {
				usage();
				return -1;
			}
			if (set_option(c, a, argv[++i]))
				return -1;
		} else {
			c->path = a;
		}
	}
	if (!c->path) {
		usage();
		return -1;
	}
	return 0;
}

static int open_csv(struct out *o, const struct cli *c)
{
	o->n_axes = c->cfg.n_axes;
	if (!c->csv)
		return 0;
	o->csv = strcmp(c->csv, "-") == 0 ? stdout : fopen(c->csv, "w");
	if (!o->csv) {
		perror(c->csv);
		return -1;
	}
	fprintf(o->csv, "cycle,status,line");
	for (unsigned k = 0; k < c->cfg.n_axes; k++)
		fprintf(o->csv, ",p%c", "XYZABC"[k]);
	for (unsigned k = 0; k < c->cfg.n_axes; k++)
		fprintf(o->csv, ",v%c", "XYZABC"[k]);
	fputc('\n', o->csv);
	return 0;
}

/* The host's side of the stream: send while the controller says XON. */
struct feeder {
	FILE *in;
	char *buf;
	size_t chunk, have, off;
	bool eof, ended;
};

static void feed(struct motion *m, struct feeder *f)
{
	while (!f->ended && motion_stream_flow(m) == MOTION_FLOW_XON) {
		if (f->off == f->have && !f->eof) {
			f->have = fread(f->buf, 1, f->chunk, f->in);
			f->off = 0;
			f->eof = f->have == 0;
		}
		if (f->off == f->have) {
			motion_stream_end(m);
			f->ended = true;
			break;
		}
		long w = motion_stream_write(m, f->buf + f->off, f->have - f->off);

		if (w <= 0)
			break;
		f->off += (size_t)w;
	}
}

/* Feed and run cycles until the program ends, faults, underruns or the
 * cycle budget is spent; returns the last status, *cycles the count. */
static enum motion_status run(struct motion *m, struct feeder *f, struct out *o, const struct cli *c,
			      unsigned long long *cycles)
{
	enum motion_status st = MOTION_ST_IDLE;
	struct motion_setpoint sp;

	*cycles = 0;
	for (;;) {
		feed(m, f);
		if (c->workers) {
			sleep_us(1000);
			st = (enum motion_status)atomic_load(&o->status);
			*cycles = atomic_load(&o->count);
		} else {
			st = motion_next_setpoint(m, &sp);
			write_sp(o, &sp);
			(*cycles)++;
		}
		if (st == MOTION_ST_DONE || st == MOTION_ST_FAULT || st == MOTION_ST_UNDERRUN)
			return st;
		if (c->max_cycles && *cycles >= c->max_cycles)
			return st;
	}
}

static void print_summary(struct motion *m, enum motion_status st, unsigned long long cycles, uint32_t period_us)
{
	struct motion_stats s;

	motion_get_stats(m, &s);
	fprintf(stderr,
		"%s: %llu lines, %llu blocks, %llu segments, %llu cycles (%.3f s), "
		"xoff %llu, xon %llu, underruns %llu\n",
		st == MOTION_ST_DONE ? "done" : "stopped",
		(unsigned long long)s.lines, (unsigned long long)s.blocks,
		(unsigned long long)s.segments, cycles,
		(double)cycles * period_us * 1e-6, (unsigned long long)s.xoff_events,
		(unsigned long long)s.xon_events, (unsigned long long)s.underruns);
	fprintf(stderr, "peak queue levels:");
	for (unsigned q = 0; q < MOTION_N_QUEUES; q++)
		fprintf(stderr, " %s %u/%u", motion_queue_name(q), s.peak[q], s.cap[q]);
	fputc('\n', stderr);
}

static int write_trace(struct motion *m, const char *path)
{
	FILE *f = fopen(path, "w");
	int rc = 0;

	if (!f || motion_trace_csv(m, f)) {
		perror(path);
		rc = 2;
	}
	if (f)
		fclose(f);
	return rc;
}

int main(int argc, char **argv)
{
	struct cli c;
	struct out o;
	struct feeder f;
	struct motion *m = NULL;
	struct motion_error err;
	unsigned long long cycles = 0;
	enum motion_status st;
	int rc = 2;

	memset(&o, 0, sizeof(o));
	memset(&f, 0, sizeof(f));
	if (parse_args(&c, argc, argv))
		return 2;
	f.chunk = c.chunk;
	f.in = strcmp(c.path, "-") == 0 ? stdin : fopen(c.path, "rb");
	if (!f.in) {
		perror(c.path);
		return 2;
	}
	f.buf = malloc(c.chunk);
	if (!f.buf || open_csv(&o, &c))
		goto out;
	if (c.trace)
		c.cfg.trace_samples = 1u << 20;
	if (c.workers) {
		c.cfg.send_cb = send_cb;
		c.cfg.send_user = &o;
	}
	if (motion_create(&c.cfg, &m, &err)) {
		fprintf(stderr, "motion_cli: %s\n", err.msg);
		goto out;
	}
	if (c.workers && motion_start(m, c.workers)) {
		fprintf(stderr, "motion_cli: cannot start %u workers\n", c.workers);
		goto out;
	}
	st = run(m, &f, &o, &c, &cycles);
	if (c.workers)
		motion_stop(m);
	rc = 0;
	const struct motion_error *e = motion_last_error(m);
	if (e) {
		fprintf(stderr, "%s:%u:%u: error: %s\n", c.path, e->line, e->column, e->msg);
		rc = 1;
	} else if (st != MOTION_ST_DONE) {
		fprintf(stderr, "motion_cli: stopped after %llu cycles\n", cycles);
		rc = 1;
	}
	if (c.trace && write_trace(m, c.trace))
		rc = 2;
	if (!c.quiet)
		print_summary(m, st, cycles, c.cfg.period_us);
out:
	if (o.csv && o.csv != stdout)
		fclose(o.csv);
	if (f.in != stdin)
		fclose(f.in);
	free(f.buf);
	if (m)
		motion_destroy(m);
	return rc;
}
