// SPDX-License-Identifier: MIT
/*
 * telem_feed - the stand-in producer for host tests: the REAL telemetry ring
 * and server (libtelem.a) streaming N synthetic cycles at a given rate. The
 * plant: axes 0/1 follow a circle, the others sines, each through a
 * first-order lag (following error), with velocity, current, latencies and
 * exchange statuses made up in the program.
 *
 *   telem_feed [--addr A] [--port P] [--cycles N] [--rate HZ] [--axes N]
 *              [--ring CAP] [--wait-clients K] [--wait-timeout S]
 *              [--restart-at CYCLE] [--param-every N] [--log-every N]
 *              [--queues-every N] [--burst] [--linger-ms MS] [--id NAME]
 *              [--client-buffer BYTES] [--stats-ms MS] [--start-cycle C]
 *              [--token STR] [--auth-ms MS] [--stall-ms MS] [--params] [--hold]
 *              [--publish-delay-us US] [--no-snapshot]
 *
 * --params answers REQUEST frames like servod's parameter service, for one
 * parameter (pos_kp, f32 in [0, 1000] 1/s): "param list", "param get
 * pos_kp", "param set pos_kp V" (a set is published as a PARAM event), also
 * while --wait-clients holds the cycles back. --hold: after the last cycle
 * the server stays up (statistics, requests) until SIGINT/SIGTERM.
 * Prints "listening 127.0.0.1 PORT" (flushed) when ready, and at the end one
 * JSON line: {"pushed":..,"dropped":..,"drained":..,"client_lost":..,...}.
 * --burst pushes as fast as it can (drops when the drain thread falls behind).
 * The application counters (exchanges, stale, missed, restarts, cycles) are
 * published as servod does, with a seqcount (telem_cfg.app_seq) around each
 * cycle's push and counter changes, so a STATS message's "cycles" equals its
 * pushed total; --publish-delay-us holds each cycle between its push and its
 * counters (a slow application: the window a snapshot must not fall in), and
 * --no-snapshot leaves app_seq out (to show what it is for).
 * SIGINT/SIGTERM end the run early (still a clean telem_stop).
 */
#define _GNU_SOURCE
#include <errno.h>
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "servoamp/mono_clock.h"
#include "telem.h"

static volatile sig_atomic_t stop_flag;

static unsigned long long STRTOULL(const char *s)
{
	return strtoull(s, NULL, 10);
}

static void on_signal(int sig)
{
	(void)sig;
	stop_flag = 1;
}

struct opts {
	const char *addr, *id;
	unsigned port, axes, ring, wait_clients, client_buffer, stats_ms, linger_ms;
	double rate, wait_timeout;
	unsigned long long cycles, restart_at, param_every, log_every, queues_every, start_cycle;
	int burst;
	const char *token;
	unsigned auth_ms, stall_ms;
	int params, hold;
	unsigned publish_delay_us;
	int no_snapshot;
};

/* --params: servod's "param" requests (params.c) for one parameter. */
static double feed_kp = 50.0;

static void serve_params(struct telem *t)
{
	struct telem_request r;

	while (telem_pop_request(t, &r)) {
		char out[256], name[40] = "", val[40] = "", v2[40] = "", *end;
		int32_t st = 0;
		int n;

		n = sscanf(r.text, "param %39s %39s %39s", name, val, v2);
		if (n >= 1 && !strcmp(name, "list")) {
			snprintf(out, sizeof(out), "%-3s %-16s %-4s %-10s %-12s %-12s %-12s %s\n"
				 "3   %-16s f32  %-10s %-12s %-12s %-12s %.9g\n", "id", "name", "type", "unit",
				 "min", "max", "default", "value", "pos_kp", "1/s", "0", "1000", "50", feed_kp);
		} else if (n == 2 && !strcmp(name, "get") && !strcmp(val, "pos_kp")) {
			snprintf(out, sizeof(out), "pos_kp=%.9g 1/s\n", feed_kp);
		} else if (n == 3 && !strcmp(name, "set") && !strcmp(val, "pos_kp")) {
			double v = strtod(v2, &end);

			if (*end || !(v >= 0.0 && v <= 1000.0)) {
				st = 6;	/* SE_VALUE */
				snprintf(out, sizeof(out), "pos_kp: %s out of range [0, 1000] 1/s", v2);
			} else {
				feed_kp = (double)(float)v;
				telem_push_param(t, 0, 3, "pos_kp", TELEM_P_F32, feed_kp, "1/s");
				snprintf(out, sizeof(out), "pos_kp=%.9g 1/s\n", feed_kp);
			}
		} else {
			st = 1;	/* SE_USAGE */
			snprintf(out, sizeof(out), "usage: param list | param get NAME | param set NAME VALUE");
		}
		telem_reply(t, &r, st, out, strlen(out));
	}
}

struct app {
	_Atomic unsigned long long exchanges, stale, missed, restarts, cycles;	/* read by the drain thread */
	_Atomic uint64_t seq;	/* odd while a cycle is pushed and counted */
};

/* the seqcount, seq_cst like the counters (telem_cfg.app_seq) */
static void app_bump(struct app *a)
{
	atomic_store(&a->seq, atomic_load_explicit(&a->seq, memory_order_relaxed) + 1u);
}

static uint64_t app_seq(void *arg)
{
	struct app *a = arg;

	return atomic_load(&a->seq);
}

static unsigned app_counters(void *arg, struct telem_counter *out, unsigned max)
{
	const struct app *a = arg;
	const char *names[] = { "exchanges", "stale", "missed", "restarts", "cycles" };
	unsigned long long v[] = { a->exchanges, a->stale, a->missed, a->restarts, a->cycles };
	unsigned n = 5u < max ? 5u : max;

	for (unsigned i = 0; i < n; i++) {
		snprintf(out[i].name, sizeof(out[i].name), "%s", names[i]);
		out[i].value = v[i];
	}
	return n;
}

/* xorshift64*: deterministic noise */
static uint64_t rng_state = 0x9e3779b97f4a7c15ull;
static double noise(void)
{
	rng_state ^= rng_state >> 12;
	rng_state ^= rng_state << 25;
	rng_state ^= rng_state >> 27;
	return (double)((rng_state * 2685821657736338717ull) >> 11) / 9007199254740992.0 - 0.5;
}

static int usage(void)
{
	fprintf(stderr, "usage: telem_feed [--addr A] [--port P] [--cycles N] [--rate HZ] [--axes N] "
			"[--ring CAP] [--wait-clients K] [--wait-timeout S] [--restart-at C] "
			"[--param-every N] [--log-every N] [--queues-every N] [--burst] "
			"[--linger-ms MS] [--id NAME] [--client-buffer B] [--stats-ms MS] [--start-cycle C] "
			"[--token STR] [--auth-ms MS] [--stall-ms MS] [--params] [--hold] "
			"[--publish-delay-us US] [--no-snapshot]\n");
	return 2;
}

int main(int argc, char **argv)
{
	struct opts o = { "127.0.0.1", "telem_feed", 0, 4, 4096, 0, 1u << 20, 500, 2000,
			  1000.0, 10.0, 1000, 0, 0, 0, 0, 0, 0, NULL, 0, 0, 0, 0, 0, 0 };
	struct app app = { 0, 0, 0, 0, 0, 0 };
	struct telem_cfg cfg;
	static struct telem t;
	struct telem_cycle rec;
	struct telem_stats st;
	double act[AMP_MAX_AXES] = { 0 }, prev_act[AMP_MAX_AXES] = { 0 }, prev_vel[AMP_MAX_AXES] = { 0 };
	struct timespec next;
	uint64_t period_ns, t0;
	uint32_t servo_cycle = 0, servo_ticks = 0;
	unsigned long long sent = 0;
	int rc;

	for (int i = 1; i < argc; i++) {
		const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
#define NUM(name, field, conv) \
		if (!strcmp(a, name)) { if (!v) return usage(); o.field = conv(v); i++; continue; }
		NUM("--port", port, (unsigned)atoi)
		NUM("--axes", axes, (unsigned)atoi)
		NUM("--ring", ring, (unsigned)atoi)
		NUM("--wait-clients", wait_clients, (unsigned)atoi)
		NUM("--client-buffer", client_buffer, (unsigned)atoi)
		NUM("--stats-ms", stats_ms, (unsigned)atoi)
		NUM("--linger-ms", linger_ms, (unsigned)atoi)
		NUM("--auth-ms", auth_ms, (unsigned)atoi)
		NUM("--stall-ms", stall_ms, (unsigned)atoi)
		NUM("--publish-delay-us", publish_delay_us, (unsigned)atoi)
		NUM("--rate", rate, atof)
		NUM("--wait-timeout", wait_timeout, atof)
		NUM("--cycles", cycles, STRTOULL)
		NUM("--restart-at", restart_at, STRTOULL)
		NUM("--param-every", param_every, STRTOULL)
		NUM("--log-every", log_every, STRTOULL)
		NUM("--queues-every", queues_every, STRTOULL)
		NUM("--start-cycle", start_cycle, STRTOULL)
		if (!strcmp(a, "--addr") && v) { o.addr = v; i++; continue; }
		if (!strcmp(a, "--id") && v) { o.id = v; i++; continue; }
		if (!strcmp(a, "--token") && v) { o.token = v; i++; continue; }
		if (!strcmp(a, "--burst")) { o.burst = 1; continue; }
		if (!strcmp(a, "--params")) { o.params = 1; continue; }
		if (!strcmp(a, "--hold")) { o.hold = 1; continue; }
		if (!strcmp(a, "--no-snapshot")) { o.no_snapshot = 1; continue; }
		return usage();
	}
	if (o.axes < 1 || o.axes > AMP_MAX_AXES || o.rate <= 0.0 || o.port > 65535 ||
	    o.publish_delay_us > 999999u)
		return usage();

	telem_cfg_defaults(&cfg);
	cfg.listen_addr = o.addr;
	cfg.port = (uint16_t)o.port;
	cfg.controller_id = o.id;
	cfg.n_axes = o.axes;
	period_ns = (uint64_t)(1e9 / o.rate);
	cfg.cycle_period_ns = (uint32_t)period_ns;
	cfg.clock_hz = 100000000u;	/* synthetic servo tick: 100 MHz */
	cfg.ring_capacity = o.ring;
	cfg.client_buffer = o.client_buffer;
	cfg.stats_interval_ms = o.stats_ms;
	cfg.linger_ms = o.linger_ms;
	if (o.token) {
		cfg.token = o.token;
		cfg.token_len = (uint32_t)strlen(o.token);
	}
	if (o.auth_ms)
		cfg.auth_timeout_ms = o.auth_ms;
	if (o.stall_ms)
		cfg.stall_timeout_ms = o.stall_ms;
	cfg.app_counters = app_counters;
	cfg.app_seq = o.no_snapshot ? NULL : app_seq;
	cfg.app_arg = &app;
	cfg.requests = o.params;
	rc = telem_init(&t, &cfg);
	if (rc) {
		fprintf(stderr, "telem_feed: telem_init: %s\n", strerror(-rc));
		return 1;
	}
	signal(SIGINT, on_signal);
	signal(SIGTERM, on_signal);
	signal(SIGPIPE, SIG_IGN);
	if (telem_start(&t)) {
		fprintf(stderr, "telem_feed: telem_start failed\n");
		return 1;
	}
	printf("listening %s %u\n", o.addr, (unsigned)telem_port(&t));
	fflush(stdout);

	if (o.wait_clients) {
		uint64_t end = mono_now_ns() + (uint64_t)(o.wait_timeout * 1e9);

		for (;;) {
			telem_get_stats(&t, &st);
			if (st.clients >= o.wait_clients || stop_flag)
				break;
			if (mono_now_ns() > end) {
				fprintf(stderr, "telem_feed: no client after %.1f s\n", o.wait_timeout);
				telem_destroy(&t);
				return 3;
			}
			if (o.params)	/* servod answers requests with no cycle running too */
				serve_params(&t);
			usleep(2000);
		}
		usleep(20000);	/* let the drain thread send the HELLO first */
	}
	telem_push_log(&t, 0, TELEM_LOG_INFO, "rpu_app", "servoamp rpu_app (telem_feed synthetic) started", 48);

	clock_gettime(CLOCK_MONOTONIC, &next);
	t0 = (uint64_t)next.tv_sec * 1000000000u + (uint64_t)next.tv_nsec;
	for (unsigned long long k = 0; k < o.cycles && !stop_flag; k++) {
		unsigned long long cyc = o.start_cycle + k;
		double tt = (double)k * (double)period_ns * 1e-9;
		double w = 2.0 * M_PI * 0.5;	/* 0.5 Hz circle */
		uint64_t t_now;

		if (!o.burst) {
			next.tv_nsec += (long)period_ns;
			while (next.tv_nsec >= 1000000000L) {
				next.tv_nsec -= 1000000000L;
				next.tv_sec++;
			}
			while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, NULL) == EINTR && !stop_flag)
				;
		}
		/*
		 * A paced cycle's time is its deadline on the controller's clock, as
		 * a controller running at the rate would stamp it: when the host is
		 * late, the cycle is late to the server but its time stays on the
		 * grid (the rate the bridge works out from it is the feed's rate,
		 * whatever the host's load). A burst has no clock but the host's.
		 */
		t_now = o.burst ? mono_now_ns() : t0 + (uint64_t)(k + 1) * period_ns;
		app_bump(&app);	/* odd: the record and the counters are one change */
		if (o.restart_at && cyc == o.start_cycle + o.restart_at) {
			/* the servo restarted: its counter starts again; servod marks it */
			telem_push_gap(&t, t_now, cyc, cyc, 0, TELEM_GAP_CONTROLLER_RESTART);
			telem_push_log(&t, t_now, TELEM_LOG_WARNING, "servod", "servo re-attached (attach_count 2)", 34);
			servo_cycle = 0;
			app.restarts++;
		}
		memset(&rec, 0, sizeof(rec));
		rec.cycle = cyc;
		rec.t_ns = t_now;
		rec.servo_cycle = servo_cycle++;
		servo_ticks += (uint32_t)(period_ns / 10u);
		rec.t_cycle = servo_ticks;
		rec.irq_latency = (uint32_t)(150.0 + 60.0 * noise() + ((cyc % 977u) == 0 ? 900.0 : 0.0));
		rec.wake_latency_ns = (uint32_t)(12000.0 + 8000.0 * noise() + ((cyc % 1499u) == 0 ? 60000.0 : 0.0));
		rec.exchange = TELEM_X_FRESH;
		if (cyc % 997u == 5u) {
			rec.exchange = TELEM_X_STALE;
			app.stale++;
		} else if (cyc % 2003u == 7u) {
			rec.exchange = TELEM_X_MISSED;
			rec.missed = 1;
			app.missed++;
		} else {
			app.exchanges++;
		}
		rec.servo_status = 0x534e5552u;	/* AMP_SSTATE_RUNNING */
		rec.result = 0;
		rec.n_axes = o.axes;
		for (unsigned i = 0; i < o.axes; i++) {
			double target, vel_ff, vel, acc;
			double R = 100000.0;	/* increments */

			if (i == 0) {
				target = R * cos(w * tt);
				vel_ff = -R * w * sin(w * tt);
			} else if (i == 1) {
				target = R * sin(w * tt);
				vel_ff = R * w * cos(w * tt);
			} else {
				double f = 0.2 * (double)i;

				target = 20000.0 * sin(2.0 * M_PI * f * tt + (double)i);
				vel_ff = 20000.0 * 2.0 * M_PI * f * cos(2.0 * M_PI * f * tt + (double)i);
			}
			if (k == 0)
				act[i] = target;	/* the plant starts on the path */
			prev_act[i] = act[i];
			act[i] += (target - act[i]) * 0.08 + 3.0 * noise();
			vel = (act[i] - prev_act[i]) * o.rate;
			acc = (vel - prev_vel[i]) * o.rate;
			prev_vel[i] = vel;
			rec.cmd[i].control_word = AMP_AXIS_ENABLE;
			rec.cmd[i].target_pos = (int32_t)lround(target);
			rec.cmd[i].vel_ff = (int32_t)lround(vel_ff);
			rec.cmd[i].torque_offset = 0;
			rec.fb[i].status_word = 0x27u;
			rec.fb[i].actual_pos = (int32_t)lround(act[i]);
			rec.fb[i].actual_vel = (int32_t)lround(vel);
			rec.fb[i].current = (int32_t)lround(acc * 0.002 + 50.0 * noise());
			rec.fb[i].following_error = rec.cmd[i].target_pos - rec.fb[i].actual_pos;
		}
		telem_push_cycle(&t, &rec);
		sent++;
		if (o.publish_delay_us) {
			struct timespec d = { 0, (long)o.publish_delay_us * 1000L };

			nanosleep(&d, NULL);
		}
		app.cycles = sent;
		app_bump(&app);	/* even */
		if (o.params)
			serve_params(&t);
		if (o.param_every && k && k % o.param_every == 0) {
			double kp = 60.0 + (double)(k / o.param_every);

			telem_push_param(&t, t_now, 3, "pos_kp", TELEM_P_F32, kp, "1/s");
		}
		if (o.log_every && k && k % o.log_every == 0) {
			char line[96];
			int n = snprintf(line, sizeof(line), "heartbeat: cycle %llu", cyc);

			telem_push_log(&t, t_now, TELEM_LOG_INFO, "rpu_app", line, (size_t)n);
		}
		if (o.queues_every && k % o.queues_every == 0) {
			struct telem_queue_level q[3] = {
				{ "blocks", (uint32_t)(30.0 + 20.0 * sin(tt)), 256 },
				{ "segments", (uint32_t)(60.0 + 40.0 * sin(tt * 1.3)), 1024 },
				{ "setpoints", (uint32_t)(8.0 + 4.0 * cos(tt * 2.0)), 64 },
			};

			telem_push_queues(&t, t_now, q, 3);
		}
	}
	while (o.hold && !stop_flag) {	/* the cycles stopped, the server did not */
		if (o.params)
			serve_params(&t);
		usleep(2000);
	}
	telem_stop(&t);
	telem_get_stats(&t, &st);
	printf("{\"sent\":%llu,\"pushed\":%llu,\"dropped\":%llu,\"drained\":%llu,"
	       "\"client_lost\":%llu,\"events\":%llu,\"events_dropped\":%llu,"
	       "\"bytes_sent\":%llu,\"clients_total\":%llu,\"ring_high_water\":%u,"
	       "\"first_cycle\":%llu,\"last_cycle\":%llu,\"auth_failed\":%llu,\"auth_timeout\":%llu,"
	       "\"evicted\":%llu,\"refused\":%llu,\"stalled\":%llu,\"protocol\":%llu}\n",
	       sent, (unsigned long long)st.pushed, (unsigned long long)st.dropped,
	       (unsigned long long)st.drained, (unsigned long long)st.client_lost,
	       (unsigned long long)st.events, (unsigned long long)st.events_dropped,
	       (unsigned long long)st.bytes_sent, (unsigned long long)st.clients_total,
	       st.ring_high_water, o.start_cycle, o.start_cycle + (sent ? sent - 1 : 0),
	       (unsigned long long)st.auth_failed, (unsigned long long)st.auth_timeout,
	       (unsigned long long)st.evicted, (unsigned long long)st.refused,
	       (unsigned long long)st.stalled, (unsigned long long)st.protocol);
	fflush(stdout);
	telem_destroy(&t);
	return 0;
}
