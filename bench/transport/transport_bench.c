// SPDX-License-Identifier: MIT
/*
 * transport_bench - round-trip latency of amp_lib against its physical
 * floor and against kernel IPC, measured in one run with two processes
 * pinned to two cores:
 *   (a) amp_lib periodic exchange (command down, feedback up)
 *   (b) amp_lib mailbox request/response, 16-byte and 512-byte payloads
 *   (c) raw cache-line ping-pong (the floor)
 *   (d) eventfd ping-pong
 *   (e) pipe ping-pong
 * (a) and (c) run in alternating blocks within one run (a c a c ..., the
 * same peer process on the same core throughout), because the floor (c)
 * itself moves several-fold between runs on a shared machine: the ratio
 * a/c is taken per block pair, and its median and spread over the blocks
 * are reported. (b), (d) and (e) run once each afterwards.
 * Prints p50/p99/p99.9/max in ns and the ratios a/c, b/c, b512/b16, d/a, and writes
 * them as JSON (bench/README.md: "figures" schema) to the path given with
 * --json.
 *
 *   transport_bench [--iters N] [--blocks B] [--json FILE]
 *
 * --iters: round trips per measurement (for a and c: in all blocks
 * together); --blocks: number of a/c block pairs (default 20).
 */
#include <errno.h>
#include <inttypes.h>
#include <sched.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/eventfd.h>
#include <signal.h>
#include <sys/mman.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "amp/amp.h"
#include "servoamp/mono_clock.h"

struct shared {
	_Alignas(64) uint32_t ping;
	_Alignas(64) uint32_t pong;
	_Alignas(64) uint32_t stop;
	/* interleaved blocks: main writes (generation << 2 | kind) */
	_Alignas(64) uint32_t go;
	_Alignas(64) uint8_t ocm[AMP_OCM_SIZE];
};

enum { BLK_RAW = 1, BLK_PERIODIC = 2, BLK_QUIT = 3 };

static struct shared *sh;
static long n_iters = 100000;
static long n_blocks = 20;
/* round trips discarded at the start of every block (peer switching
 * over, caches warming) */
#define BLOCK_WARMUP 200L

static void pin(int cpu)
{
	long n = sysconf(_SC_NPROCESSORS_ONLN);
	cpu_set_t set;

	if (n < 2)
		return;
	CPU_ZERO(&set);
	CPU_SET(cpu % (int)n, &set);
	sched_setaffinity(0, sizeof(set), &set);
}

static int cmp_u64(const void *a, const void *b)
{
	uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;

	return x < y ? -1 : x > y;
}

struct result {
	const char *name;
	uint64_t p50, p99, p999, max;
};

static struct result percentiles(const char *name, uint64_t *v, long n)
{
	struct result r = { name, 0, 0, 0, 0 };

	qsort(v, (size_t)n, sizeof(*v), cmp_u64);
	r.p50 = v[n / 2];
	r.p99 = v[(long)((double)n * 0.99)];
	r.p999 = v[(long)((double)n * 0.999)];
	r.max = v[n - 1];
	return r;
}

static struct result summarise(const char *name, uint64_t *v, long n)
{
	struct result r = percentiles(name, v, n);

	printf("%-26s p50 %8" PRIu64 "  p99 %8" PRIu64 "  p99.9 %8" PRIu64 "  max %9" PRIu64 " ns\n",
	       name, r.p50, r.p99, r.p999, r.max);
	return r;
}

static uint32_t ld(const uint32_t *p)
{
	return __atomic_load_n(p, __ATOMIC_ACQUIRE);
}

static void st(uint32_t *p, uint32_t v)
{
	__atomic_store_n(p, v, __ATOMIC_RELEASE);
}

/*
 * ---- (a) amp_lib periodic exchange and (c) raw cache-line ping-pong,
 * in alternating blocks ----
 *
 * One peer process serves both: it waits for the next block's command in
 * sh->go, then runs the servo side of (a) until sh->go changes, or answers
 * the block's (c) round trips. The raw sequence numbers continue across
 * blocks, so both sides count them the same way.
 */
static void block_peer(void)
{
	struct amp_servo s;
	struct amp_rx_info rx;
	struct amp_fb_axis fb[AMP_MAX_AXES] = { { 0 } };
	long per_block = n_iters / n_blocks + BLOCK_WARMUP;
	uint32_t seen = 0, raw_seq = 0;

	while (amp_servo_attach(&s, sh->ocm, sizeof(sh->ocm)) != AMP_OK)
		sched_yield();
	st(&sh->stop, 1); /* attached */
	for (;;) {
		uint32_t g;

		while ((g = ld(&sh->go)) == seen)
			AMP_PORT_RELAX();
		seen = g;
		if ((g & 3u) == BLK_QUIT)
			return;
		if ((g & 3u) == BLK_RAW) {
			for (long i = 0; i < per_block; i++) {
				raw_seq++;
				while (ld(&sh->ping) != raw_seq)
					AMP_PORT_RELAX();
				st(&sh->pong, raw_seq);
			}
			continue;
		}
		while (ld(&sh->go) == g) {
			if (ld(&s.ocm->linux_line.cmd_pub) == s.cmd_seq) {
				AMP_PORT_RELAX();
				continue;
			}
			amp_servo_cycle_rx(&s, 0, &rx);
			fb[0].actual_pos = s.cmd.axis[0].target_pos;
			amp_servo_cycle_tx(&s, fb, AMP_MAX_AXES, 0, 0);
		}
	}
}

static void raw_block(uint64_t *v, long n, uint32_t *raw_seq)
{
	for (long i = -BLOCK_WARMUP; i < n; i++) {
		uint32_t seq = ++*raw_seq;
		uint64_t t0 = mono_now_ns();

		st(&sh->ping, seq);
		while (ld(&sh->pong) != seq)
			AMP_PORT_RELAX();
		if (i >= 0)
			v[i] = mono_now_ns() - t0;
	}
}

static void periodic_block(struct amp_linux *l, uint64_t *v, long n, int32_t *pos)
{
	struct amp_cmd_axis cmd[AMP_MAX_AXES] = { { 0 } };
	struct amp_rx_info rx;

	for (long i = -BLOCK_WARMUP; i < n; i++) {
		uint64_t t0 = mono_now_ns();

		cmd[0].target_pos = ++*pos;
		amp_linux_cycle(l, cmd, AMP_MAX_AXES, 0, &rx);
		while (ld(&l->ocm->cyc_sem.sem) != AMP_SEM_IDLE)
			AMP_PORT_RELAX();
		if (i >= 0)
			v[i] = mono_now_ns() - t0;
	}
}

static int cmp_double(const void *a, const void *b)
{
	double x = *(const double *)a, y = *(const double *)b;

	return x < y ? -1 : x > y;
}

/* median, quartiles and range of n per-block values */
struct spread {
	double median, q1, q3, min, max;
};

static double quantile(const double *sorted, long n, double q)
{
	double pos = q * (double)(n - 1);
	long lo = (long)pos;
	double frac = pos - (double)lo;

	return lo + 1 < n ? sorted[lo] + frac * (sorted[lo + 1] - sorted[lo]) : sorted[lo];
}

static struct spread spread_of(const double *v, long n, double *tmp)
{
	struct spread s;

	memcpy(tmp, v, (size_t)n * sizeof(*tmp));
	qsort(tmp, (size_t)n, sizeof(*tmp), cmp_double);
	s.median = quantile(tmp, n, 0.5);
	s.q1 = quantile(tmp, n, 0.25);
	s.q3 = quantile(tmp, n, 0.75);
	s.min = tmp[0];
	s.max = tmp[n - 1];
	return s;
}

struct blocks {
	struct result a, c;			/* pooled over all blocks */
	uint64_t *a50, *c50, *a999, *c999;	/* per block */
	double *r50, *r999;			/* a/c per block pair */
	struct spread s50, s999, sc50;
};

static void pooled_copy(uint64_t *dst, const uint64_t *src, long n)
{
	memcpy(dst, src, (size_t)n * sizeof(*dst));
}

static int run_blocks(struct amp_linux *l, struct blocks *b)
{
	long per = n_iters / n_blocks;
	uint64_t *va = calloc((size_t)(per * n_blocks), sizeof(*va));
	uint64_t *vc = calloc((size_t)(per * n_blocks), sizeof(*vc));
	uint64_t *tmp = calloc((size_t)per, sizeof(*tmp));
	double *dtmp = calloc((size_t)n_blocks, sizeof(*dtmp));
	double *c50d = calloc((size_t)n_blocks, sizeof(*c50d));
	uint32_t gen = 0, raw_seq = 0;
	int32_t pos = 0;
	pid_t p;

	b->a50 = calloc((size_t)n_blocks, sizeof(uint64_t));
	b->c50 = calloc((size_t)n_blocks, sizeof(uint64_t));
	b->a999 = calloc((size_t)n_blocks, sizeof(uint64_t));
	b->c999 = calloc((size_t)n_blocks, sizeof(uint64_t));
	b->r50 = calloc((size_t)n_blocks, sizeof(double));
	b->r999 = calloc((size_t)n_blocks, sizeof(double));
	if (!va || !vc || !tmp || !dtmp || !c50d || !b->a50 || !b->c50 || !b->a999 ||
	    !b->c999 || !b->r50 || !b->r999)
		return -1;

	p = fork();
	if (p < 0)
		return -1;
	if (p == 0) {
		prctl(PR_SET_PDEATHSIG, SIGKILL); /* never outlive a failed run */
		pin(1);
		block_peer();
		_exit(0);
	}
	while (!ld(&sh->stop))
		sched_yield();
	for (long k = 0; k < n_blocks; k++) {
		uint64_t *a = va + k * per, *c = vc + k * per;
		struct result ra, rc;

		st(&sh->go, (++gen << 2) | BLK_PERIODIC);
		periodic_block(l, a, per, &pos);
		st(&sh->go, (++gen << 2) | BLK_RAW);
		raw_block(c, per, &raw_seq);

		pooled_copy(tmp, a, per);
		ra = percentiles("a", tmp, per);
		pooled_copy(tmp, c, per);
		rc = percentiles("c", tmp, per);
		b->a50[k] = ra.p50;
		b->c50[k] = rc.p50;
		b->a999[k] = ra.p999;
		b->c999[k] = rc.p999;
		b->r50[k] = (double)ra.p50 / (double)(rc.p50 ? rc.p50 : 1);
		b->r999[k] = (double)ra.p999 / (double)(rc.p999 ? rc.p999 : 1);
		c50d[k] = (double)rc.p50;
	}
	st(&sh->go, (++gen << 2) | BLK_QUIT);
	waitpid(p, NULL, 0);

	b->a = summarise("(a) amp periodic exchange", va, per * n_blocks);
	b->c = summarise("(c) cache-line ping-pong", vc, per * n_blocks);
	b->s50 = spread_of(b->r50, n_blocks, dtmp);
	b->s999 = spread_of(b->r999, n_blocks, dtmp);
	b->sc50 = spread_of(c50d, n_blocks, dtmp);
	printf("a/c over %ld block pairs of %ld round trips (a then c, alternating):\n", n_blocks, per);
	printf("  p50:   median %.2f  IQR %.2f-%.2f  min %.2f  max %.2f\n",
	       b->s50.median, b->s50.q1, b->s50.q3, b->s50.min, b->s50.max);
	printf("  p99.9: median %.2f  IQR %.2f-%.2f  min %.2f  max %.2f\n",
	       b->s999.median, b->s999.q1, b->s999.q3, b->s999.min, b->s999.max);
	printf("  floor (c) p50 per block: median %.0f  min %.0f  max %.0f ns\n",
	       b->sc50.median, b->sc50.min, b->sc50.max);
	free(va);
	free(vc);
	free(tmp);
	free(dtmp);
	free(c50d);
	return 0;
}

/* ---- (b) amp_lib mailbox ---- */
static void mbox_peer(void)
{
	struct amp_servo s;
	struct amp_mbox_req req;
	uint8_t buf[AMP_MBOX_CAPACITY];

	while (amp_servo_attach(&s, sh->ocm, sizeof(sh->ocm)) != AMP_OK)
		sched_yield();
	st(&sh->pong, 1);
	while (!ld(&sh->stop)) {
		if (amp_servo_mbox_poll(&s, &req) != 1) {
			AMP_PORT_RELAX();
			continue;
		}
		for (uint32_t i = 0; i < req.length; i++)
			buf[i] = req.payload[i];
		amp_servo_mbox_respond(&s, 0, buf, req.length);
	}
}

static struct result mbox_run(struct amp_linux *l, uint32_t len, const char *name, uint64_t *v)
{
	uint8_t out[AMP_MBOX_CAPACITY], in[AMP_MBOX_CAPACITY];
	struct amp_msg req = { .command = 1, .length = len, .data = out };
	struct amp_msg resp = { .capacity = sizeof(in), .data = in };

	memset(out, 0x5a, sizeof(out));
	while (!ld(&sh->pong))
		sched_yield();
	for (long i = -1000; i < n_iters; i++) {
		uint64_t t0 = mono_now_ns();

		/* 30 s (POSIX port ticks are us): a latency measurement, not a
		 * timeout test; a shared host can stall the peer over a second */
		if (amp_linux_mbox_call(l, &req, &resp, 30000000) != AMP_OK) {
			fprintf(stderr, "mailbox call failed\n");
			exit(1);
		}
		if (i >= 0)
			v[i] = mono_now_ns() - t0;
	}
	return summarise(name, v, n_iters);
}

/* ---- (d) eventfd and (e) pipe ---- */
static int fds[4];

static void kernel_peer(int use_eventfd)
{
	for (long i = 0; i < n_iters + 1000; i++) {
		uint64_t x;

		if (use_eventfd) {
			if (read(fds[0], &x, 8) != 8 || write(fds[1], &x, 8) != 8)
				_exit(1);
		} else {
			char c;

			if (read(fds[0], &c, 1) != 1 || write(fds[3], &c, 1) != 1)
				_exit(1);
		}
	}
}

static struct result kernel_run(int use_eventfd, uint64_t *v)
{
	for (long i = -1000; i < n_iters; i++) {
		uint64_t t0 = mono_now_ns(), x = 1;
		int ok;

		if (use_eventfd) {
			ok = write(fds[0], &x, 8) == 8 && read(fds[1], &x, 8) == 8;
		} else {
			char c = 'x';

			ok = write(fds[1], &c, 1) == 1 && read(fds[2], &c, 1) == 1;
		}
		if (!ok) {
			perror("kernel ping-pong");
			exit(1);
		}
		if (i >= 0)
			v[i] = mono_now_ns() - t0;
	}
	return summarise(use_eventfd ? "(d) eventfd ping-pong" : "(e) pipe ping-pong", v, n_iters);
}

/* eventfd ping-pong needs two counters: fds[0] main->peer, fds[1] back.
 * The peer reads fds[0] and writes fds[1]; the main side the reverse. */
static pid_t spawn(void (*fn)(void), int arg_eventfd, int kernel)
{
	pid_t p = fork();

	if (p == 0) {
		prctl(PR_SET_PDEATHSIG, SIGKILL); /* never outlive a failed run */
		pin(1);
		if (kernel)
			kernel_peer(arg_eventfd);
		else
			fn();
		_exit(0);
	}
	return p;
}

static void reset_shared(void)
{
	memset(sh, 0, sizeof(*sh));
}

static void json_u64_array(FILE *f, const char *key, const uint64_t *v, long n, const char *end)
{
	fprintf(f, "    \"%s\": [", key);
	for (long i = 0; i < n; i++)
		fprintf(f, "%s%" PRIu64, i ? ", " : "", v[i]);
	fprintf(f, "]%s\n", end);
}

static void json_spread(FILE *f, const char *key, const struct spread *s, const double *per,
			long n, const char *end)
{
	fprintf(f, "    \"%s\": {\"median\": %.3f, \"q1\": %.3f, \"q3\": %.3f, \"min\": %.3f, "
		"\"max\": %.3f, \"per_block\": [", key, s->median, s->q1, s->q3, s->min, s->max);
	for (long i = 0; i < n; i++)
		fprintf(f, "%s%.3f", i ? ", " : "", per[i]);
	fprintf(f, "]}%s\n", end);
}

/* one entry of the "figures" list (bench/README.md) */
static void json_figure(FILE *f, const char *name, double value, const char *unit,
			const char *better, const struct spread *s, const char *note, int last)
{
	fprintf(f, "    {\"name\": \"%s\", \"value\": %.3f, \"unit\": \"%s\", \"better\": \"%s\"",
		name, value, unit, better);
	if (s)
		fprintf(f, ", \"spread\": {\"min\": %.3f, \"q1\": %.3f, \"q3\": %.3f, \"max\": %.3f}",
			s->min, s->q1, s->q3, s->max);
	if (note)
		fprintf(f, ", \"note\": \"%s\"", note);
	fprintf(f, "}%s\n", last ? "" : ",");
}

int main(int argc, char **argv)
{
	const char *json = NULL;
	struct result r[6];
	struct blocks blk;
	struct amp_linux l;
	uint64_t *v;
	pid_t p;
	FILE *f;

	for (int i = 1; i < argc; i++) {
		if (!strcmp(argv[i], "--iters") && i + 1 < argc)
			n_iters = atol(argv[++i]);
		else if (!strcmp(argv[i], "--blocks") && i + 1 < argc)
			n_blocks = atol(argv[++i]);
		else if (!strcmp(argv[i], "--json") && i + 1 < argc)
			json = argv[++i];
		else {
			fprintf(stderr, "usage: transport_bench [--iters N] [--blocks B] [--json FILE]\n");
			return 2;
		}
	}
	if (n_iters < 1000) {
		fprintf(stderr, "transport_bench: --iters must be >= 1000\n");
		return 2;
	}
	if (n_blocks < 1 || n_iters / n_blocks < 100) {
		fprintf(stderr, "transport_bench: --blocks must be >= 1 with >= 100 round trips per block\n");
		return 2;
	}
	sh = mmap(NULL, sizeof(*sh), PROT_READ | PROT_WRITE, MAP_SHARED | MAP_ANONYMOUS, -1, 0);
	v = calloc((size_t)n_iters, sizeof(*v));
	if (sh == MAP_FAILED || !v)
		return 2;
	setvbuf(stdout, NULL, _IONBF, 0);
	printf("transport_bench: %ld round trips each, (a) and (c) in %ld alternating block pairs, "
	       "%ld CPUs online\n", n_iters, n_blocks, sysconf(_SC_NPROCESSORS_ONLN));
	pin(0);

	reset_shared();
	amp_linux_init(&l, sh->ocm, sizeof(sh->ocm), 1000000);
	if (run_blocks(&l, &blk)) {
		fprintf(stderr, "transport_bench: out of memory or fork failed\n");
		return 2;
	}
	r[0] = blk.a;
	r[2] = blk.c;

	reset_shared();
	amp_linux_init(&l, sh->ocm, sizeof(sh->ocm), 1000000);
	p = spawn(mbox_peer, 0, 0);
	r[1] = mbox_run(&l, 16, "(b) amp mailbox 16 B", v);
	r[5] = mbox_run(&l, 512, "(b) amp mailbox 512 B", v);
	st(&sh->stop, 1);
	waitpid(p, NULL, 0);

	fds[0] = eventfd(0, 0);
	fds[1] = eventfd(0, 0);
	p = spawn(NULL, 1, 1);
	r[3] = kernel_run(1, v);
	waitpid(p, NULL, 0);
	close(fds[0]);
	close(fds[1]);

	{
		int a[2], b[2];

		if (pipe(a) || pipe(b))
			return 2;
		fds[0] = a[0];
		fds[1] = a[1];
		fds[2] = b[0];
		fds[3] = b[1];
		p = spawn(NULL, 0, 1);
		r[4] = kernel_run(0, v);
		waitpid(p, NULL, 0);
	}

	/* pooled ratios (all blocks together) and per-block medians */
	double ac50 = (double)r[0].p50 / (double)r[2].p50;
	double ac999 = (double)r[0].p999 / (double)r[2].p999;
	double bc50 = (double)r[1].p50 / (double)r[2].p50;
	double b512c50 = (double)r[5].p50 / (double)r[2].p50;
	double da50 = (double)r[3].p50 / (double)r[0].p50;
	double b512b16 = (double)r[5].p50 / (double)r[1].p50;

	printf("ratios: a/c p50 %.2f (median of blocks; pooled %.2f), a/c p99.9 %.2f (median of "
	       "blocks; pooled %.2f), b16/c p50 %.2f, b512/b16 p50 %.2f, d/a p50 %.1f\n",
	       blk.s50.median, ac50, blk.s999.median, ac999, bc50, b512b16, da50);
	if (json) {
		char note50[160], note999[160];

		f = fopen(json, "w");
		if (!f) {
			perror(json);
			return 2;
		}
		fprintf(f, "{\n  \"benchmark\": \"transport\",\n  \"iterations\": %ld,\n  \"cpus\": %ld,\n"
			"  \"unit\": \"ns\",\n  \"latency\": {\n",
			n_iters, sysconf(_SC_NPROCESSORS_ONLN));
		const char *keys[6] = { "a_amp_periodic", "b_amp_mailbox_16", "c_cacheline_pingpong",
					"d_eventfd", "e_pipe", "b_amp_mailbox_512" };
		for (int i = 0; i < 6; i++)
			fprintf(f, "    \"%s\": {\"p50\": %" PRIu64 ", \"p99\": %" PRIu64
				", \"p99_9\": %" PRIu64 ", \"max\": %" PRIu64 "}%s\n", keys[i],
				r[i].p50, r[i].p99, r[i].p999, r[i].max, i < 5 ? "," : "");
		fprintf(f, "  },\n  \"ratios\": {\"a_over_c_p50\": %.3f, \"a_over_c_p99_9\": %.3f, "
			"\"b16_over_c_p50\": %.3f, \"b512_over_c_p50\": %.3f, \"b512_over_b16_p50\": %.3f, "
			"\"d_over_a_p50\": %.3f},\n",
			ac50, ac999, bc50, b512c50, b512b16, da50);
		fprintf(f, "  \"blocks\": {\n    \"pairs\": %ld,\n    \"round_trips_per_block\": %ld,\n"
			"    \"warmup_per_block\": %ld,\n    \"order\": \"a then c in every pair\",\n",
			n_blocks, n_iters / n_blocks, BLOCK_WARMUP);
		json_u64_array(f, "a_p50_ns", blk.a50, n_blocks, ",");
		json_u64_array(f, "c_p50_ns", blk.c50, n_blocks, ",");
		json_u64_array(f, "a_p99_9_ns", blk.a999, n_blocks, ",");
		json_u64_array(f, "c_p99_9_ns", blk.c999, n_blocks, ",");
		json_spread(f, "a_over_c_p50", &blk.s50, blk.r50, n_blocks, ",");
		json_spread(f, "a_over_c_p99_9", &blk.s999, blk.r999, n_blocks, "");
		fprintf(f, "  },\n  \"figures\": [\n");
		snprintf(note50, sizeof(note50), "median of %ld a/c block pairs (pooled %.2f)",
			 n_blocks, ac50);
		snprintf(note999, sizeof(note999), "median of %ld a/c block pairs (pooled %.2f)",
			 n_blocks, ac999);
		json_figure(f, "a_over_c_p50", blk.s50.median, "x", "lower", &blk.s50, note50, 0);
		json_figure(f, "a_over_c_p99_9", blk.s999.median, "x", "lower", &blk.s999, note999, 0);
		json_figure(f, "d_over_a_p50", da50, "x", "higher", NULL, NULL, 0);
		json_figure(f, "b16_over_c_p50", bc50, "x", "lower", NULL, NULL, 0);
		json_figure(f, "b512_over_b16_p50", b512b16, "x", "lower", NULL,
			    "the 512-byte mailbox round trip over the 16-byte one", 0);
		json_figure(f, "a_periodic_p50", (double)r[0].p50, "ns", "lower", NULL,
			    "pooled over the blocks", 0);
		json_figure(f, "c_floor_p50", (double)r[2].p50, "ns", "lower", &blk.sc50,
			    "pooled; spread: per-block p50", 0);
		json_figure(f, "b16_mailbox_p50", (double)r[1].p50, "ns", "lower", NULL, NULL, 0);
		json_figure(f, "b512_mailbox_p50", (double)r[5].p50, "ns", "lower", NULL, NULL, 0);
		json_figure(f, "d_eventfd_p50", (double)r[3].p50, "ns", "lower", NULL, NULL, 1);
		fprintf(f, "  ]\n}\n");
		fclose(f);
	}
	free(v);
	return 0;
}
