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
 * Prints p50/p99/p99.9/max in ns and the ratios a/c, b/c, d/a, and writes
 * them as JSON to the path given with --json.
 *
 *   transport_bench [--iters N] [--json FILE]
 */
#include <errno.h>
#include <inttypes.h>
#include <sched.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/eventfd.h>
#include <sys/mman.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "amp/amp.h"
#include "servoamp/mono_clock.h"

struct shared {
	_Alignas(64) uint32_t ping;
	_Alignas(64) uint32_t pong;
	_Alignas(64) uint32_t stop;
	_Alignas(64) uint8_t ocm[AMP_OCM_SIZE];
};

static struct shared *sh;
static long n_iters = 100000;

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

static struct result summarise(const char *name, uint64_t *v, long n)
{
	struct result r = { name, 0, 0, 0, 0 };

	qsort(v, (size_t)n, sizeof(*v), cmp_u64);
	r.p50 = v[n / 2];
	r.p99 = v[(long)((double)n * 0.99)];
	r.p999 = v[(long)((double)n * 0.999)];
	r.max = v[n - 1];
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

/* ---- (c) raw cache-line ping-pong ---- */
static void raw_peer(void)
{
	for (uint32_t i = 1; i <= (uint32_t)n_iters + 1000u; i++) {
		while (ld(&sh->ping) != i)
			AMP_PORT_RELAX();
		st(&sh->pong, i);
	}
}

static struct result raw_run(uint64_t *v)
{
	for (uint32_t i = 1; i <= (uint32_t)n_iters + 1000u; i++) {
		uint64_t t0 = mono_now_ns();

		st(&sh->ping, i);
		while (ld(&sh->pong) != i)
			AMP_PORT_RELAX();
		if (i > 1000u)
			v[i - 1001u] = mono_now_ns() - t0;
	}
	return summarise("(c) cache-line ping-pong", v, n_iters);
}

/* ---- (a) amp_lib periodic exchange ---- */
static void periodic_peer(void)
{
	struct amp_servo s;
	struct amp_rx_info rx;
	struct amp_fb_axis fb[AMP_MAX_AXES] = { { 0 } };

	while (amp_servo_attach(&s, sh->ocm, sizeof(sh->ocm)) != AMP_OK)
		sched_yield();
	st(&sh->pong, 1);
	while (!ld(&sh->stop)) {
		if (ld(&s.ocm->linux_line.cmd_pub) == s.cmd_seq) {
			AMP_PORT_RELAX();
			continue;
		}
		amp_servo_cycle_rx(&s, 0, &rx);
		fb[0].actual_pos = s.cmd.axis[0].target_pos;
		amp_servo_cycle_tx(&s, fb, AMP_MAX_AXES, 0, 0);
	}
}

static struct result periodic_run(struct amp_linux *l, uint64_t *v)
{
	struct amp_cmd_axis cmd[AMP_MAX_AXES] = { { 0 } };
	struct amp_rx_info rx;

	while (!ld(&sh->pong))
		sched_yield();
	for (long i = -1000; i < n_iters; i++) {
		uint64_t t0 = mono_now_ns();

		cmd[0].target_pos = (int32_t)i;
		amp_linux_cycle(l, cmd, AMP_MAX_AXES, 0, &rx);
		while (ld(&l->ocm->cyc_sem.sem) != AMP_SEM_IDLE)
			AMP_PORT_RELAX();
		if (i >= 0)
			v[i] = mono_now_ns() - t0;
	}
	return summarise("(a) amp periodic exchange", v, n_iters);
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

		if (amp_linux_mbox_call(l, &req, &resp, 1000000) != AMP_OK) {
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

int main(int argc, char **argv)
{
	const char *json = NULL;
	struct result r[6];
	struct amp_linux l;
	uint64_t *v;
	pid_t p;
	FILE *f;

	for (int i = 1; i < argc; i++) {
		if (!strcmp(argv[i], "--iters") && i + 1 < argc)
			n_iters = atol(argv[++i]);
		else if (!strcmp(argv[i], "--json") && i + 1 < argc)
			json = argv[++i];
		else {
			fprintf(stderr, "usage: transport_bench [--iters N] [--json FILE]\n");
			return 2;
		}
	}
	if (n_iters < 1000) {
		fprintf(stderr, "transport_bench: --iters must be >= 1000\n");
		return 2;
	}
	sh = mmap(NULL, sizeof(*sh), PROT_READ | PROT_WRITE, MAP_SHARED | MAP_ANONYMOUS, -1, 0);
	v = calloc((size_t)n_iters, sizeof(*v));
	if (sh == MAP_FAILED || !v)
		return 2;
	setvbuf(stdout, NULL, _IONBF, 0);
	printf("transport_bench: %ld round trips each, %ld CPUs online\n", n_iters,
	       sysconf(_SC_NPROCESSORS_ONLN));
	pin(0);

	reset_shared();
	p = spawn(raw_peer, 0, 0);
	r[2] = raw_run(v);
	waitpid(p, NULL, 0);

	reset_shared();
	amp_linux_init(&l, sh->ocm, sizeof(sh->ocm), 1000000);
	p = spawn(periodic_peer, 0, 0);
	r[0] = periodic_run(&l, v);
	st(&sh->stop, 1);
	waitpid(p, NULL, 0);

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

	double ac50 = (double)r[0].p50 / (double)r[2].p50;
	double ac999 = (double)r[0].p999 / (double)r[2].p999;
	double bc50 = (double)r[1].p50 / (double)r[2].p50;
	double da50 = (double)r[3].p50 / (double)r[0].p50;

	printf("ratios: a/c p50 %.2f (target <= 2), a/c p99.9 %.2f (target <= 3), "
	       "b16/c p50 %.2f, d/a p50 %.1f (target >= 10)\n", ac50, ac999, bc50, da50);
	if (json) {
		f = fopen(json, "w");
		if (!f) {
			perror(json);
			return 2;
		}
		fprintf(f, "{\n  \"iterations\": %ld,\n  \"cpus\": %ld,\n  \"unit\": \"ns\",\n  \"latency\": {\n",
			n_iters, sysconf(_SC_NPROCESSORS_ONLN));
		const char *keys[6] = { "a_amp_periodic", "b_amp_mailbox_16", "c_cacheline_pingpong",
					"d_eventfd", "e_pipe", "b_amp_mailbox_512" };
		for (int i = 0; i < 6; i++)
			fprintf(f, "    \"%s\": {\"p50\": %" PRIu64 ", \"p99\": %" PRIu64
				", \"p99_9\": %" PRIu64 ", \"max\": %" PRIu64 "}%s\n", keys[i],
				r[i].p50, r[i].p99, r[i].p999, r[i].max, i < 5 ? "," : "");
		fprintf(f, "  },\n  \"ratios\": {\"a_over_c_p50\": %.3f, \"a_over_c_p99_9\": %.3f, "
			"\"b16_over_c_p50\": %.3f, \"b512_over_c_p50\": %.3f, \"d_over_a_p50\": %.3f}\n}\n",
			ac50, ac999, bc50, (double)r[5].p50 / (double)r[2].p50, da50);
		fclose(f);
	}
	free(v);
	return 0;
}
