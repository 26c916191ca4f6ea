/* SPDX-License-Identifier: MIT */
/*
 * motion_bench: throughput of the motion pipeline and speed-up of the
 * hybrid scheduler.  Prints figures and writes them as JSON; it asserts
 * nothing about timing.
 *
 *   motion_bench [--blocks N] [--arcs N] [--reps R] [--workers W]
 *                [--batch B] [--queue Q] [--chord UM]
 *                [--only trapezoid|scurve] [--json PATH]
 *
 * 1. blocks/s through the whole pipeline on one thread (synchronous mode,
 *    the caller consumes every setpoint), on a mixed program of N blocks,
 *    with trapezoidal and with S-curve profiles;
 * 2. a planning-heavy program (N short arcs, fine chord tolerance) on the
 *    worker pool, setpoints drained by a sink task: hybrid on W workers vs
 *    1, and vs a plain FIFO schedule on W workers.  It runs twice, with
 *    trapezoidal and with jerk-limited (S-curve) profiles; in the second,
 *    planning (look-ahead and accel) is most of the work.  Each
 *    configuration runs R times, interleaved; the best time counts.
 */
#define _POSIX_C_SOURCE 200809L
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "motion/motion.h"
#include "scheduler.h" /* sched_decide(): the model runs the real rules */
#include "servoamp/mono_clock.h"

static double now_s(void)
{
	return (double)mono_now_ns() * 1e-9;
}

static double cpu_s(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
	return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

static char *append(char *p, size_t *len, size_t *cap, const char *line)
{
	size_t l = strlen(line);

	if (*len + l + 1 > *cap) {
		size_t nc = (*cap ? *cap * 2 : 65536) + l;
		char *q = realloc(p, nc);
		if (!q) {
			free(p);
			return NULL;
		}
		p = q;
		*cap = nc;
	}
	memcpy(p + *len, line, l + 1);
	*len += l;
	return p;
}

/* lines, arcs and a dwell now and then, wandering in a 100 mm square */
static char *gen_mixed(int n)
{
	char *p = NULL, line[128];
	size_t len = 0, cap = 0;
	uint32_t s = 7;
	double x = 0, y = 0;

	p = append(p, &len, &cap, "G21 G90 G17 F6000\n");
	for (int i = 0; p && i < n; i++) {
		s = s * 1664525u + 1013904223u;
		double nx = fmin(100, fmax(-100, x + (double)((s >> 8) % 2001) / 100.0 - 10.0));
		s = s * 1664525u + 1013904223u;
		double ny = fmin(100, fmax(-100, y + (double)((s >> 8) % 2001) / 100.0 - 10.0));
		double d = hypot(nx - x, ny - y);
		if (i % 4 == 3 && d > 0.1)
			snprintf(line, sizeof(line), "G%d X%.3f Y%.3f R%.3f\n", i % 8 == 3 ? 2 : 3,
				 nx, ny, d * 0.75);
		else if (i % 97 == 0)
			snprintf(line, sizeof(line), "G4 P0.002\n");
		else
			snprintf(line, sizeof(line), "G1 X%.3f Y%.3f\n", nx, ny);
		if (!strncmp(line, "G4", 2)) {
			p = append(p, &len, &cap, line);
			continue;
		}
		x = nx;
		y = ny;
		p = append(p, &len, &cap, line);
	}
	return p ? append(p, &len, &cap, "M2\n") : NULL;
}

/* many short arcs along a zigzag: planning heavy */
static char *gen_arcs(int n)
{
	char *p = NULL, line[128];
	size_t len = 0, cap = 0;
	double x = 0, y = 0, dir = 1;

	p = append(p, &len, &cap, "G21 G90 G17 F6000\n");
	for (int i = 1; p && i <= n; i++) {
		if (i % 100 == 0) {
			dir = -dir;
			y += 1.0;
			snprintf(line, sizeof(line), "G1 Y%.3f\n", y);
		} else {
			x += 0.5 * dir;
			snprintf(line, sizeof(line), "G%d X%.3f Y%.3f R%.3f\n", i % 2 ? 2 : 3, x,
				 y, i % 3 ? 0.4 : -0.3);
		}
		p = append(p, &len, &cap, line);
	}
	return p ? append(p, &len, &cap, "M2\n") : NULL;
}

/* Calibration: how many cores the machine offers right now to two threads
 * of pure, independent arithmetic (no sharing): their CPU time over the
 * wall time of the parallel phase, at most 2.  Near 2 means two cores
 * were free; near 1 means the other core was busy elsewhere.  (A ratio
 * of a sequential and a parallel wall time, as before, swings both ways
 * on a loaded host: a preempted sequential phase gave "4.9x".) */
static void *spin(void *arg)
{
	volatile double x = 1.0;
	long n = *(long *)arg;

	for (long i = 0; i < n; i++)
		x = x * 1.0000001 + 1e-9;
	return NULL;
}

static double calibrate(unsigned workers)
{
	long n = 20000000;
	pthread_t th[8];
	double t0 = now_s(), c0 = cpu_s();

	for (unsigned i = 0; i < workers; i++)
		if (pthread_create(&th[i], NULL, spin, &n))
			return 0;
	for (unsigned i = 0; i < workers; i++)
		pthread_join(th[i], NULL);
	double par = now_s() - t0, cpu = cpu_s() - c0;
	return par > 0 ? cpu / par : 0;
}

struct result {
	double wall, cpu;
	uint64_t blocks, segments, setpoints, checksum;
	uint64_t busy_ns[MOTION_N_TASKS];
	uint64_t jobs[MOTION_MAX_WORKERS];
	uint64_t idle[MOTION_MAX_WORKERS];
	uint64_t job_ns[MOTION_MAX_WORKERS], sched_ns[MOTION_MAX_WORKERS],
		sleep_ns[MOTION_MAX_WORKERS];
	const char *names[MOTION_N_TASKS];
	unsigned n_tasks;
};

static int run_sync(const struct motion_config *c, const char *prog, struct result *r)
{
	struct motion *m;
	struct motion_error e;
	struct motion_setpoint sp;
	enum motion_status st;
	struct motion_stats s;

	memset(r, 0, sizeof(*r));
	if (motion_create(c, &m, &e) || motion_load_program(m, prog, strlen(prog)))
		return -1;
	double t0 = now_s(), c0 = cpu_s();
	while ((st = motion_next_setpoint(m, &sp)) == MOTION_ST_MOVING ||
	       st == MOTION_ST_IDLE)
		if (st == MOTION_ST_MOVING)
			r->checksum = motion_setpoint_hash(r->checksum, &sp);
	r->wall = now_s() - t0;
	r->cpu = cpu_s() - c0;
	motion_get_stats(m, &s);
	r->blocks = s.blocks;
	r->segments = s.segments;
	r->setpoints = s.setpoints;
	int rc = st == MOTION_ST_DONE ? 0 : -1;
	if (rc)
		fprintf(stderr, "sync run: %s\n",
			motion_last_error(m) ? motion_last_error(m)->msg : "did not finish");
	motion_destroy(m);
	return rc;
}

static int run_pool(struct motion_config c, const char *prog, unsigned workers,
		    enum motion_policy pol, uint32_t min_job, uint32_t lanes,
		    struct result *r)
{
	struct motion *m;
	struct motion_error e;
	struct motion_stats s;

	memset(r, 0, sizeof(*r));
	c.drain_sink = true;
	c.policy = pol;
	c.min_job = min_job;
	c.interp_lanes = lanes;
	if (motion_create(&c, &m, &e) || motion_load_program(m, prog, strlen(prog)))
		return -1;
	double t0 = now_s(), c0 = cpu_s();
	if (motion_start(m, workers))
		return -1;
	/* sleep until the sink has taken the last setpoint: a polling loop
	 * here would wake every few hundred microseconds on a core that the
	 * workers need */
	if (motion_wait(m, 600000u) || motion_last_error(m)) {
		fprintf(stderr, "pool run: %s\n", motion_last_error(m) ?
			motion_last_error(m)->msg : "did not finish in 600 s");
		motion_destroy(m);
		return -1;
	}
	r->wall = now_s() - t0;
	motion_stop(m);
	r->cpu = cpu_s() - c0;
	motion_get_stats(m, &s);
	r->blocks = s.blocks;
	r->segments = s.segments;
	r->setpoints = s.setpoints;
	r->checksum = motion_sink_checksum(m);
	r->n_tasks = s.n_tasks;
	for (unsigned t = 0; t < s.n_tasks; t++) {
		r->busy_ns[t] = s.busy_ns[t];
		r->names[t] = s.task_name[t];
		for (unsigned w = 0; w < MOTION_MAX_WORKERS; w++)
			r->jobs[w] += s.runs[t][w];
	}
	for (unsigned w = 0; w < MOTION_MAX_WORKERS; w++) {
		r->idle[w] = s.idle[w];
		r->job_ns[w] = s.job_ns[w];
		r->sched_ns[w] = s.sched_ns[w];
		r->sleep_ns[w] = s.sleep_ns[w];
	}
	int rc = motion_last_error(m) ? -1 : 0;
	motion_destroy(m);
	return rc;
}

#define N_CFG 6

/* Figures of one scheduler experiment (one program, one profile kind). */
struct sched_figures {
	const char *key, *profile;
	struct cfgs {
		const char *name;
		unsigned w;
		enum motion_policy pol;
		uint32_t min_job; /* 0: the default (whole jobs of batch items) */
		uint32_t lanes;   /* interpolation lanes */
		struct result best;
	} cf[N_CFG];
	struct result ref;
	double inflation, sched_share, sp_h, sp_r2, sp_f, sp_1lane, bound, calib;
	double share[MOTION_N_TASKS];
	/* the N-worker model (model_print()) */
	double cost_ms[MOTION_N_TASKS]; /* CPU time per task, 1 worker */
	double model[9], model_adj[9], model_one[9], model_acc[9]; /* by workers, 1..8 */
};

/* ---- the N-worker model ------------------------------------------------
 *
 * From the per-task costs of the 1-worker run (CPU time: each task's share
 * of the time in jobs times the run's CPU time, so that a preempted run
 * still gives its costs).  The serial tasks (decode, fit, look-ahead,
 * accel, sink) run on one core at a time (rule 1); the work of the profile
 * lanes (peak0..) and of the interpolation lanes (interp0..) splits over
 * min(N, lanes) cores.  Over a long program the time on N workers is at
 * least each of
 *   W / N               (all the work over N cores),
 *   C_max               (the largest serial task),
 *   C_lanes / lanes     (each lane stage, one lane per worker: lanes = N),
 * and the model takes the largest (a critical-path bound for a pipeline
 * whose fill and drain are short against the run).  "Adjusted" inflates
 * every cost by f(N) = 1 + (i2 - 1)(N - 1), where i2 is the measured time
 * in jobs on 2 workers over 1 worker: each further core costs what the
 * second one did.  "One interp task" is the same bound with the
 * interpolation as one serial task (the design before the interpolation
 * lanes); "profiles in accel" with the profile lanes' work done by accel
 * (the design before the profile lanes). */
static double model_bound(double W, double cmax, double interp, unsigned n,
			  unsigned lanes)
{
	double t = W / n;
	if (cmax > t)
		t = cmax;
	if (interp / lanes > t)
		t = interp / lanes;
	return t > 0 ? W / t : 0;
}

static void model_print(struct sched_figures *x, unsigned workers)
{
	const struct result *h1 = &x->cf[0].best;
	double W = 0, cmax = 0, interp = 0, peak = 0, accel = 0;
	const char *cmax_name = "?";

	for (unsigned t = 0; t < h1->n_tasks; t++) {
		double c = x->share[t] * h1->cpu * 1e3;
		x->cost_ms[t] = c;
		W += c;
		if (!strncmp(h1->names[t], "interp", 6)) {
			interp += c;
		} else if (!strncmp(h1->names[t], "peak", 4)) {
			peak += c;
		} else if (c > cmax) {
			cmax = c;
			cmax_name = h1->names[t];
		}
		if (!strcmp(h1->names[t], "accel"))
			accel = c;
	}
	double i2 = workers >= 2 && x->inflation > 1 ? x->inflation : 1.0;
	printf("  N-worker model from the 1-worker costs (CPU ms: total %.1f, largest serial task %s %.1f, profiles %.1f and interpolation %.1f over the lanes; i2 = %.2f):\n",
	       W, cmax_name, cmax, peak, interp, i2);
	printf("    workers          ");
	for (unsigned n = 1; n <= 8; n++)
		printf(" %5u", n);
	printf("\n    bound            ");
	for (unsigned n = 1; n <= 8; n++) {
		x->model[n] = model_bound(W, cmax, interp, n, n);
		printf(" %5.2f", x->model[n]);
	}
	printf("\n    adjusted         ");
	for (unsigned n = 1; n <= 8; n++) {
		x->model_adj[n] = x->model[n] / (1.0 + (i2 - 1.0) * (n - 1));
		printf(" %5.2f", x->model_adj[n]);
	}
	printf("\n    one interp       ");
	for (unsigned n = 1; n <= 8; n++) {
		double c1 = interp > cmax ? interp : cmax;
		x->model_one[n] = model_bound(W, c1, interp, n, 1);
		printf(" %5.2f", x->model_one[n]);
	}
	printf("\n    profiles in accel");
	for (unsigned n = 1; n <= 8; n++) {
		double ca = accel + peak > cmax ? accel + peak : cmax;
		x->model_acc[n] = model_bound(W, ca, interp, n, n);
		printf(" %5.2f", x->model_acc[n]);
	}
	printf("\n");
	if (workers <= 8)
		printf("    measured on %u workers: %.3f, %.0f%% of the bound, %.0f%% of the adjusted figure\n",
		       workers, x->sp_h, 100.0 * x->sp_h / x->model[workers],
		       100.0 * x->sp_h / x->model_adj[workers]);
}

/* The source design's workload (seed 003): 6 chained data tasks, 150
 * items placed upstream, every job one item of the same cost (a delay
 * loop).  An event simulation on n workers with the hybrid rules
 * (sched_decide(), the library's own) and queues of `cap` items; returns
 * the makespan in job costs.  Its speed-up on 4 is the model's figure for
 * the source's 3.895. */
#define SRC_TASKS 6
static double model_source(unsigned n, int items, uint32_t cap)
{
	uint32_t q[SRC_TASKS + 1] = { (uint32_t)items };
	bool running[SRC_TASKS] = { false };
	double end[SRC_TASKS] = { 0 };
	uint64_t last[SRC_TASKS] = { 0 }, seq = 0;
	unsigned idle = n;
	double t = 0;

	for (;;) {
		while (idle > 0) {
			struct sched_dstate d[SRC_TASKS];
			for (int i = 0; i < SRC_TASKS; i++) {
				d[i].order = (uint8_t)i;
				d[i].ul = q[i];
				d[i].dl = i + 1 == SRC_TASKS ? 0 : q[i + 1];
				d[i].dcap = i + 1 == SRC_TASKS ? 1 : cap;
				d[i].running = running[i];
				d[i].last = last[i];
			}
			struct sched_choice c = sched_decide(MOTION_POLICY_HYBRID, NULL, 0,
							     d, SRC_TASKS);
			if (c.kind != SCHED_CHOICE_DATA)
				break;
			running[c.index] = true;
			last[c.index] = ++seq;
			q[c.index]--;
			end[c.index] = t + 1.0;
			idle--;
		}
		double next = -1;
		for (int i = 0; i < SRC_TASKS; i++)
			if (running[i] && (next < 0 || end[i] < next))
				next = end[i];
		if (next < 0)
			break;
		t = next;
		for (int i = 0; i < SRC_TASKS; i++)
			if (running[i] && end[i] <= t) {
				running[i] = false;
				q[i + 1]++;
				idle++;
			}
	}
	return t;
}

static double source_speedup[9];

static void model_source_print(void)
{
	const int items = 150;
	double t1 = model_source(1, items, 1000);

	printf("source design's workload (seed 003: 6 equal chained tasks, 150 items upstream, 3.895x measured on 4 cores), simulated with the hybrid rules:\n    workers    ");
	for (unsigned n = 1; n <= 8; n++)
		printf(" %5u", n);
	printf("\n    speed-up   ");
	for (unsigned n = 1; n <= 8; n++) {
		source_speedup[n] = t1 / model_source(n, items, 1000);
		printf(" %5.3f", source_speedup[n]);
	}
	printf("\n    on 4 workers: %.3f predicted against 3.895 measured (%.1f%%)\n",
	       source_speedup[4], 100.0 * 3.895 / source_speedup[4]);
}

/* Runs the program on the pool in six configurations (hybrid on 1 and W
 * workers, FIFO on 1 and W, hybrid with rule 2 as written on W, hybrid on
 * 1 worker with 1 interpolation lane), R times interleaved, best time
 * each; checks every run's setpoints against the synchronous run, and
 * prints the figures. */
static int sched_experiment(const struct motion_config *h, const char *prog,
			    unsigned workers, int reps, struct sched_figures *x)
{
	struct cfgs *cf = x->cf;

	memset(cf, 0, sizeof(x->cf));
	cf[0].name = "hybrid_1"; cf[0].w = 1; cf[0].pol = MOTION_POLICY_HYBRID;
	cf[1].name = "hybrid_n"; cf[1].w = workers; cf[1].pol = MOTION_POLICY_HYBRID;
	cf[2].name = "fifo_1"; cf[2].w = 1; cf[2].pol = MOTION_POLICY_FIFO;
	cf[3].name = "fifo_n"; cf[3].w = workers; cf[3].pol = MOTION_POLICY_FIFO;
	/* the hybrid scheduler's rule 2 as written: a task may run on a single item */
	cf[4].name = "hybrid_n_rule2"; cf[4].w = workers; cf[4].pol = MOTION_POLICY_HYBRID;
	cf[4].min_job = 1;
	/* the pipeline as it was before the lanes, on 1 worker */
	cf[5].name = "hybrid_1_1lane"; cf[5].w = 1; cf[5].pol = MOTION_POLICY_HYBRID;
	for (int i = 0; i < N_CFG; i++)
		cf[i].lanes = cf[i].lanes ? cf[i].lanes : (workers > 1 ? workers : 2);
	cf[5].lanes = 1;
	struct result *ref = &x->ref;
	if (run_sync(h, prog, ref))
		return 1;
	x->calib = 0;
	for (int k = 0; k < reps; k++) {
		/* the mean over the repetitions: the runs' surroundings */
		x->calib += calibrate(workers) / reps;
		for (int i = 0; i < N_CFG; i++) {
			struct result r;
			if (run_pool(*h, prog, cf[i].w, cf[i].pol, cf[i].min_job,
				     cf[i].lanes, &r)) {
				fprintf(stderr, "%s failed\n", cf[i].name);
				return 1;
			}
			if (r.checksum != ref->checksum || r.setpoints != ref->setpoints) {
				fprintf(stderr, "%s: setpoints differ from the synchronous run\n",
					cf[i].name);
				return 1;
			}
			if (k == 0 || r.wall < cf[i].best.wall)
				cf[i].best = r;
		}
	}
	printf("planning-heavy program, %s profiles: %llu arcs/lines, %llu segments, %llu setpoints\n",
	       x->profile, (unsigned long long)ref->blocks, (unsigned long long)ref->segments,
	       (unsigned long long)ref->setpoints);
	for (int i = 0; i < N_CFG; i++) {
		const struct result *b = &cf[i].best;
		printf("  %-14s %u worker(s), %u lane(s): %.3f s wall, %.3f s cpu, jobs per worker %llu/%llu, idle waits %llu/%llu\n",
		       cf[i].name, cf[i].w, cf[i].lanes, b->wall, b->cpu,
		       (unsigned long long)b->jobs[0], (unsigned long long)b->jobs[1],
		       (unsigned long long)b->idle[0], (unsigned long long)b->idle[1]);
		printf("                 worker time in jobs / scheduler path / asleep (ms):");
		for (unsigned w = 0; w < cf[i].w && w < MOTION_MAX_WORKERS; w++)
			printf("%s %.1f/%.2f/%.2f", w ? "," : "", b->job_ns[w] * 1e-6,
			       b->sched_ns[w] * 1e-6, b->sleep_ns[w] * 1e-6);
		printf("\n");
	}
	/* work inflation: job time summed over workers, n workers vs 1 */
	uint64_t job1 = 0, jobn = 0, schedn = 0;
	for (unsigned w = 0; w < MOTION_MAX_WORKERS; w++) {
		job1 += cf[0].best.job_ns[w];
		jobn += cf[1].best.job_ns[w];
		schedn += cf[1].best.sched_ns[w];
	}
	x->inflation = job1 ? (double)jobn / (double)job1 : 0;
	x->sched_share = jobn + schedn ? (double)schedn / (double)(jobn + schedn) : 0;
	printf("  hybrid, %u workers: time inside jobs %.2fx that of 1 worker for the same work "
	       "(items crossing cores, and preemption when the machine is busy); "
	       "scheduler path %.1f%% of worker time\n",
	       workers, x->inflation, 100.0 * x->sched_share);
	const struct result *h1 = &cf[1 - 1].best;
	printf("  time per task (hybrid, 1 worker):");
	uint64_t tot = 0, mx = 0;
	for (unsigned t = 0; t < h1->n_tasks; t++) {
		tot += h1->busy_ns[t];
		mx = h1->busy_ns[t] > mx ? h1->busy_ns[t] : mx;
	}
	for (unsigned t = 0; t < h1->n_tasks; t++) {
		x->share[t] = h1->busy_ns[t] / (double)tot;
		printf(" %s %.0f%%", h1->names[t], 100.0 * x->share[t]);
	}
	printf("\n");
	const struct result *hn = &cf[1].best;
	printf("  time in jobs per task, ms, 1 worker -> %u workers:", workers);
	for (unsigned t = 0; t < h1->n_tasks; t++)
		printf(" %s %.1f->%.1f", h1->names[t], h1->busy_ns[t] * 1e-6,
		       hn->busy_ns[t] * 1e-6);
	printf("\n");
	x->sp_h = cf[0].best.wall / cf[1].best.wall;
	x->sp_r2 = cf[0].best.wall / cf[4].best.wall;
	x->sp_f = cf[3].best.wall / cf[1].best.wall;
	x->sp_1lane = cf[5].best.wall / cf[1].best.wall;
	double bound = mx ? (double)tot / (double)mx : 0;
	x->bound = bound < workers ? bound : (double)workers;
	printf("  speed-up hybrid %u vs 1 worker: %.3f (bound from the largest task: %.2f)\n",
	       workers, x->sp_h, x->bound);
	printf("  speed-up without whole jobs (rule 2 as written): %.3f\n", x->sp_r2);
	printf("  hybrid vs plain FIFO, %u workers: %.3f\n", workers, x->sp_f);
	printf("  speed-up over 1 worker with 1 lane (the serial interpolator's pipeline): %.3f; 1 worker, 1 lane / %u lanes: %.3f\n",
	       x->sp_1lane, cf[0].lanes, cf[5].best.wall / cf[0].best.wall);
	printf("  calibration: %u threads of independent arithmetic got %.2f cores (CPU time over wall time,"
	       " mean of %d; what the machine offered during the runs)\n", workers, x->calib, reps);
	model_print(x, workers);
	return 0;
}

static void json_sched(FILE *f, const struct sched_figures *x, double chord_um,
		       unsigned workers, int reps, bool last)
{
	const struct cfgs *cf = x->cf;
	const struct result *h1 = &cf[0].best;

	fprintf(f, "  \"%s\": {\n    \"program\": \"short arcs, chord tolerance %g um\", \"profile\": \"%s\", \"blocks\": %llu, \"segments\": %llu, \"setpoints\": %llu, \"workers\": %u, \"reps\": %d,\n",
		x->key, chord_um, x->profile, (unsigned long long)x->ref.blocks,
		(unsigned long long)x->ref.segments, (unsigned long long)x->ref.setpoints,
		workers, reps);
	for (int i = 0; i < N_CFG; i++)
		fprintf(f, "    \"%s\": {\"workers\": %u, \"lanes\": %u, \"wall_s\": %.6f, \"cpu_s\": %.6f, \"job_ms\": [%.2f, %.2f], \"sched_ms\": [%.2f, %.2f], \"sleep_ms\": [%.2f, %.2f]},\n",
			cf[i].name, cf[i].w, cf[i].lanes, cf[i].best.wall, cf[i].best.cpu,
			cf[i].best.job_ns[0] * 1e-6, cf[i].best.job_ns[1] * 1e-6,
			cf[i].best.sched_ns[0] * 1e-6, cf[i].best.sched_ns[1] * 1e-6,
			cf[i].best.sleep_ns[0] * 1e-6, cf[i].best.sleep_ns[1] * 1e-6);
	fprintf(f, "    \"task_time_share\": {");
	for (unsigned t = 0; t < h1->n_tasks; t++)
		fprintf(f, "%s\"%s\": %.4f", t ? ", " : "", h1->names[t], x->share[t]);
	fprintf(f, "},\n");
	fprintf(f, "    \"job_time_n_over_1\": %.4f,\n", x->inflation);
	fprintf(f, "    \"scheduler_path_share_n\": %.4f,\n", x->sched_share);
	fprintf(f, "    \"speedup_hybrid_n_over_1\": %.4f,\n", x->sp_h);
	fprintf(f, "    \"speedup_hybrid_rule2_as_written_n_over_1\": %.4f,\n", x->sp_r2);
	fprintf(f, "    \"speedup_hybrid_over_fifo_n\": %.4f,\n", x->sp_f);
	fprintf(f, "    \"speedup_hybrid_n_over_1_one_lane\": %.4f,\n", x->sp_1lane);
	fprintf(f, "    \"task_cpu_ms_1_worker\": {");
	for (unsigned t = 0; t < h1->n_tasks; t++)
		fprintf(f, "%s\"%s\": %.3f", t ? ", " : "", h1->names[t], x->cost_ms[t]);
	fprintf(f, "},\n");
	const char *mk[4] = { "model_bound", "model_adjusted", "model_one_interp_task",
			      "model_profiles_in_accel" };
	const double *mv[4] = { x->model, x->model_adj, x->model_one, x->model_acc };
	for (int k = 0; k < 4; k++) {
		fprintf(f, "    \"%s_speedup_1_to_8\": [", mk[k]);
		for (unsigned n = 1; n <= 8; n++)
			fprintf(f, "%s%.4f", n > 1 ? ", " : "", mv[k][n]);
		fprintf(f, "],\n");
	}
	fprintf(f, "    \"speedup_bound_largest_task\": %.4f,\n", x->bound);
	fprintf(f, "    \"calibration_independent_threads_speedup\": %.4f\n  }%s\n",
		x->calib, last ? "" : ",");
}

int main(int argc, char **argv)
{
	int blocks = 50000, arcs = 20000, reps = 10, batch = 1024, queue = 8192;
	double chord_um = 0.2;
	const char *only = NULL; /* one profile kind only */
	unsigned workers = 2;
	const char *json = NULL;

	for (int i = 1; i < argc; i++) {
		if (!strcmp(argv[i], "--blocks") && i + 1 < argc)
			blocks = atoi(argv[++i]);
		else if (!strcmp(argv[i], "--arcs") && i + 1 < argc)
			arcs = atoi(argv[++i]);
		else if (!strcmp(argv[i], "--reps") && i + 1 < argc)
			reps = atoi(argv[++i]);
		else if (!strcmp(argv[i], "--workers") && i + 1 < argc)
			workers = (unsigned)atoi(argv[++i]);
		else if (!strcmp(argv[i], "--batch") && i + 1 < argc)
			batch = atoi(argv[++i]);
		else if (!strcmp(argv[i], "--queue") && i + 1 < argc)
			queue = atoi(argv[++i]);
		else if (!strcmp(argv[i], "--chord") && i + 1 < argc)
			chord_um = atof(argv[++i]);
		else if (!strcmp(argv[i], "--only") && i + 1 < argc)
			only = argv[++i];
		else if (!strcmp(argv[i], "--json") && i + 1 < argc)
			json = argv[++i];
		else {
			fprintf(stderr, "usage: motion_bench [--blocks N] [--arcs N] [--reps R] "
					"[--workers W] [--batch B] [--queue Q] [--chord UM] [--only trapezoid|scurve] [--json PATH]\n");
			return 2;
		}
	}
	if (blocks < 1 || arcs < 1 || reps < 1 || workers < 1 || workers > 8 || batch < 1 ||
	    queue < 16 || !(chord_um > 0) ||
	    (only && strcmp(only, "trapezoid") && strcmp(only, "scurve"))) {
		fprintf(stderr, "motion_bench: bad option value\n");
		return 2;
	}

	/* 1. one thread, whole pipeline, trapezoidal and S-curve profiles */
	struct motion_config c;
	char *mixed = gen_mixed(blocks);
	struct result single[2];
	memset(single, 0, sizeof(single));
	if (!mixed)
		return 1;
	for (int kind = 0; kind < 2; kind++) {
		struct result rs, *best = &single[kind];
		motion_config_default(&c);
		c.jerk_limited = kind == 1;
		for (int k = 0; k < reps; k++) {
			if (run_sync(&c, mixed, &rs))
				return 1;
			if (k == 0 || rs.wall < best->wall)
				*best = rs;
		}
		printf("one thread, mixed program, %s profiles: %llu blocks, %llu segments, "
		       "%llu setpoints (%.1f s of motion) in %.3f s\n",
		       kind ? "S-curve" : "trapezoidal", (unsigned long long)best->blocks,
		       (unsigned long long)best->segments, (unsigned long long)best->setpoints,
		       best->setpoints * c.period_us * 1e-6, best->wall);
		printf("  %.0f blocks/s, %.0f segments/s, %.0f setpoints/s\n",
		       best->blocks / best->wall, best->segments / best->wall,
		       best->setpoints / best->wall);
	}

	/* 2. scheduler speed-up on a planning-heavy program */
	struct motion_config h;
	motion_config_default(&h);
	h.chord_tol = chord_um * 1e-3;
	for (int k = 0; k < 3; k++)
		h.axis[k].amax = 10000;
	h.batch = (uint32_t)batch;
	for (int k = 0; k < 3; k++)
		h.axis[k].jmax = 1e6;
	h.q_blocks = (uint32_t)queue / 4;
	h.q_segments = (uint32_t)queue;
	h.q_planned = (uint32_t)queue / 2;
	h.q_profiles = (uint32_t)queue / 2;
	h.q_setpoints = (uint32_t)queue;
	char *heavy = gen_arcs(arcs);
	if (!heavy)
		return 1;
	/* the same program with trapezoidal and with jerk-limited (S-curve)
	 * profiles: the second moves most of the work into planning */
	struct sched_figures fig[2];
	unsigned nfig = 0;
	memset(fig, 0, sizeof(fig));
	for (int kind = 0; kind < 2; kind++) {
		const char *prof = kind ? "scurve" : "trapezoid";
		if (only && strcmp(only, prof))
			continue;
		struct sched_figures *x = &fig[nfig++];
		x->key = kind ? "scheduler_scurve" : "scheduler";
		x->profile = kind ? "jerk-limited (S-curve)" : "trapezoidal";
		h.jerk_limited = kind == 1;
		if (sched_experiment(&h, heavy, workers, reps, x))
			return 1;
	}
	model_source_print();
	long ncpu = sysconf(_SC_NPROCESSORS_ONLN);
	double load[1] = { -1 };
	FILE *lf = fopen("/proc/loadavg", "r");
	if (lf) {
		if (fscanf(lf, "%lf", &load[0]) != 1)
			load[0] = -1;
		fclose(lf);
	}
	printf("  machine: %ld cpus online, load average %.2f at the end\n", ncpu, load[0]);

	if (json) {
		FILE *f = fopen(json, "w");
		if (!f) {
			perror(json);
			return 1;
		}
		fprintf(f, "{\n  \"benchmark\": \"motion_bench\",\n");
		fprintf(f, "  \"command\": \"build/motion/host/motion_bench --blocks %d --arcs %d --reps %d --workers %u --batch %d --queue %d --chord %g%s%s\",\n",
			blocks, arcs, reps, workers, batch, queue, chord_um, only ? " --only " : "", only ? only : "");
		fprintf(f, "  \"machine\": {\"cpus_online\": %ld, \"loadavg_1min_at_end\": %.2f},\n", ncpu, load[0]);
		for (int kind = 0; kind < 2; kind++) {
			const struct result *r = &single[kind];
			fprintf(f, "  \"%s\": {\"program\": \"mixed lines/arcs/dwells\", \"profile\": \"%s\", \"blocks\": %llu, \"segments\": %llu, \"setpoints\": %llu, \"wall_s\": %.6f, \"blocks_per_s\": %.1f, \"segments_per_s\": %.1f, \"setpoints_per_s\": %.1f}%s\n",
				kind ? "single_thread_scurve" : "single_thread",
				kind ? "jerk-limited (S-curve)" : "trapezoidal",
				(unsigned long long)r->blocks, (unsigned long long)r->segments,
				(unsigned long long)r->setpoints, r->wall, r->blocks / r->wall,
				r->segments / r->wall, r->setpoints / r->wall,
				kind == 0 || nfig ? "," : "");
		}
		for (unsigned i = 0; i < nfig; i++)
			json_sched(f, &fig[i], chord_um, workers, reps, i + 1 == nfig);
		/* the summary table's figures (bench/README.md); targets in
		 * bench/targets.toml */
		fprintf(f, ",\n  \"figures\": [\n");
		for (int kind = 0; kind < 2; kind++)
			fprintf(f, "    {\"name\": \"blocks_per_s_1thread_%s\", \"value\": %.1f, "
				"\"unit\": \"1/s\", \"better\": \"higher\", \"note\": \"mixed program, whole pipeline\"},\n",
				kind ? "scurve" : "trapezoid", single[kind].blocks / single[kind].wall);
		for (unsigned i = 0; i < nfig; i++) {
			const char *kind = strcmp(fig[i].key, "scheduler") ? "scurve" : "trapezoid";

			fprintf(f, "    {\"name\": \"speedup_hybrid_%uw_%s\", \"value\": %.4f, "
				"\"unit\": \"x\", \"better\": \"higher\", \"note\": \"over 1 worker, "
				"short arcs at %g um\"},\n", workers, kind, fig[i].sp_h, chord_um);
			fprintf(f, "    {\"name\": \"speedup_hybrid_over_fifo_%uw_%s\", \"value\": %.4f, "
				"\"unit\": \"x\", \"better\": \"higher\"},\n", workers, kind, fig[i].sp_f);
			fprintf(f, "    {\"name\": \"calibration_%uthreads_%s\", \"value\": %.4f, "
				"\"unit\": \"x\", \"better\": \"higher\", \"note\": \"independent threads "
				"got this many cores (CPU over wall, mean over the repetitions): what the machine offered\"},\n", workers, kind, fig[i].calib);
			fprintf(f, "    {\"name\": \"model_speedup_4w_%s\", \"value\": %.4f, "
				"\"unit\": \"x\", \"better\": \"higher\", \"note\": \"N-worker model from "
				"the measured 1-worker task costs, lanes = workers (adjusted: %.2f; one "
				"interp task: %.2f; profiles in accel: %.2f)\"},\n", kind, fig[i].model[4],
				fig[i].model_adj[4], fig[i].model_one[4], fig[i].model_acc[4]);
		}
		fprintf(f, "    {\"name\": \"model_source_workload_4w\", \"value\": %.4f, "
			"\"unit\": \"x\", \"better\": \"higher\", \"note\": \"the model (hybrid rules, event "
			"simulation) on seed 003's workload: 6 equal tasks, 150 items; 3.895 measured there\"}\n",
			source_speedup[4]);
		fprintf(f, "  ]\n}\n");
		fclose(f);
	}
	free(mixed);
	free(heavy);
	return 0;
}
