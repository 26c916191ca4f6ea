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

int main(int argc, char **argv)
{
	struct motion_config cfg;
	const char *path = NULL, *csv = NULL, *trace = NULL;
	unsigned workers = 0;
	size_t chunk = 4096;
	unsigned long long max_cycles = 0;
	bool quiet = false;
	struct out o;

	motion_config_default(&cfg);
	for (int i = 1; i < argc; i++) {
		const char *a = argv[i];
		const char *v = i + 1 < argc ? argv[i + 1] : NULL;
#define ARG(name) (strcmp(a, name) == 0 && v && (i++, 1))
		if (ARG("--csv")) csv = v;
		else if (ARG("--trace")) trace = v;
		else if (ARG("--workers")) workers = (unsigned)atoi(v);
		else if (ARG("--policy")) cfg.policy = strcmp(v, "fifo") == 0 ? MOTION_POLICY_FIFO : MOTION_POLICY_HYBRID;
		else if (ARG("--period-us")) cfg.period_us = (uint32_t)atoi(v);
		else if (ARG("--scale")) cfg.increments_per_mm = atof(v);
		else if (ARG("--vmax")) for (int k = 0; k < MOTION_MAX_AXES; k++) cfg.axis[k].vmax = atof(v);
		else if (ARG("--amax")) for (int k = 0; k < MOTION_MAX_AXES; k++) cfg.axis[k].amax = atof(v);
		else if (ARG("--jmax")) for (int k = 0; k < MOTION_MAX_AXES; k++) cfg.axis[k].jmax = atof(v);
		else if (ARG("--travel")) for (int k = 0; k < MOTION_MAX_AXES; k++) { cfg.axis[k].min = -atof(v); cfg.axis[k].max = atof(v); }
		else if (ARG("--tol")) cfg.chord_tol = atof(v);
		else if (ARG("--axes")) cfg.n_axes = (uint32_t)atoi(v);
		else if (ARG("--chunk")) chunk = (size_t)atol(v);
		else if (ARG("--max-cycles")) max_cycles = strtoull(v, NULL, 10);
		else if (strcmp(a, "--jerk") == 0) cfg.jerk_limited = true;
		else if (strcmp(a, "--quiet") == 0) quiet = true;
		else if (a[0] == '-' && a[1]) { usage(); return 2; }
		else path = a;
#undef ARG
	}
	if (!path || chunk == 0) {
		usage();
		return 2;
	}
	FILE *in = strcmp(path, "-") == 0 ? stdin : fopen(path, "rb");
	if (!in) {
		perror(path);
		return 2;
	}
	memset(&o, 0, sizeof(o));
	o.n_axes = cfg.n_axes;
	if (csv) {
		o.csv = strcmp(csv, "-") == 0 ? stdout : fopen(csv, "w");
		if (!o.csv) {
			perror(csv);
			return 2;
		}
		fprintf(o.csv, "cycle,status,line");
		for (unsigned k = 0; k < cfg.n_axes; k++)
			fprintf(o.csv, ",p%c", "XYZABC"[k]);
		for (unsigned k = 0; k < cfg.n_axes; k++)
			fprintf(o.csv, ",v%c", "XYZABC"[k]);
		fputc('\n', o.csv);
	}
	if (trace)
		cfg.trace_samples = 1u << 20;
	if (workers) {
		cfg.send_cb = send_cb;
		cfg.send_user = &o;
	}
	struct motion *m;
	struct motion_error err;
	if (motion_create(&cfg, &m, &err)) {
		fprintf(stderr, "motion_cli: %s\n", err.msg);
		return 2;
	}
	if (workers && motion_start(m, workers)) {
		fprintf(stderr, "motion_cli: cannot start %u workers\n", workers);
		return 2;
	}
	char *buf = malloc(chunk);
	size_t have = 0, off = 0;
	bool eof = false, ended = false;
	enum motion_status st = MOTION_ST_IDLE;
	struct motion_setpoint sp;
	unsigned long long cycles = 0;
	if (!buf)
		return 2;
	for (;;) {
		/* host side: send while the controller says XON */
		while (!ended && motion_stream_flow(m) == MOTION_FLOW_XON) {
			if (off == have && !eof) {
				have = fread(buf, 1, chunk, in);
				off = 0;
				eof = have == 0;
			}
			if (off == have) {
				motion_stream_end(m);
				ended = true;
				break;
			}
			long w = motion_stream_write(m, buf + off, have - off);
			if (w <= 0)
				break;
			off += (size_t)w;
		}
		if (workers) {
			sleep_us(1000);
			st = (enum motion_status)atomic_load(&o.status);
			cycles = atomic_load(&o.count);
		} else {
			st = motion_next_setpoint(m, &sp);
			write_sp(&o, &sp);
			cycles++;
		}
		if (st == MOTION_ST_DONE || st == MOTION_ST_FAULT || st == MOTION_ST_UNDERRUN)
			break;
		if (max_cycles && cycles >= max_cycles)
			break;
	}
	if (workers)
		motion_stop(m);
	int rc = 0;
	const struct motion_error *e = motion_last_error(m);
	if (e) {
		fprintf(stderr, "%s:%u:%u: error: %s\n", path, e->line, e->column, e->msg);
		rc = 1;
	} else if (st != MOTION_ST_DONE) {
		fprintf(stderr, "motion_cli: stopped after %llu cycles\n", cycles);
		rc = 1;
	}
	if (trace) {
		FILE *f = fopen(trace, "w");
		if (!f || motion_trace_csv(m, f)) {
			perror(trace);
			rc = 2;
		}
		if (f)
			fclose(f);
	}
	if (!quiet) {
		struct motion_stats s;
		motion_get_stats(m, &s);
		fprintf(stderr,
			"%s: %llu lines, %llu blocks, %llu segments, %llu cycles (%.3f s), "
			"xoff %llu, xon %llu, underruns %llu\n",
			st == MOTION_ST_DONE ? "done" : "stopped",
			(unsigned long long)s.lines, (unsigned long long)s.blocks,
			(unsigned long long)s.segments, (unsigned long long)cycles,
			cycles * cfg.period_us * 1e-6, (unsigned long long)s.xoff_events,
			(unsigned long long)s.xon_events, (unsigned long long)s.underruns);
		fprintf(stderr, "peak queue levels:");
		for (unsigned q = 0; q < MOTION_N_QUEUES; q++)
			fprintf(stderr, " %s %u/%u", motion_queue_name(q), s.peak[q], s.cap[q]);
		fputc('\n', stderr);
	}
	if (o.csv && o.csv != stdout)
		fclose(o.csv);
	if (in != stdin)
		fclose(in);
	free(buf);
	motion_destroy(m);
	return rc;
}
