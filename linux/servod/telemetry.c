// SPDX-License-Identifier: MIT
/*
 * telemetry.c - servod's use of the telemetry transport (linux/telemetry,
 * docs/telemetry.md): its option, its start and stop, the cycle record
 * (cycle thread: lock-free ring, no syscall, never waits) and the events
 * of an attach (GAP and the parameter set loaded).
 */
#define _GNU_SOURCE
#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "context.h"

/* "ADDR:PORT", "[V6ADDR]:PORT" or "off" -> telem_addr / telem_port; 0 ok. */
int telemetry_parse_opt(struct servod_opts *o)
{
	const char *s = o->telem, *colon;
	char *end;
	unsigned long port;
	size_t alen;

	if (!strcmp(s, "off"))
		return 0;
	colon = strrchr(s, ':');
	if (!colon || colon == s)
		return -1;
	port = strtoul(colon + 1, &end, 10);
	if (!colon[1] || *end || port > 65535)
		return -1;
	if (s[0] == '[') {
		if (colon[-1] != ']')
			return -1;
		s++;
		alen = (size_t)(colon - 1 - s);
	} else {
		alen = (size_t)(colon - s);
	}
	if (!alen || alen >= sizeof(o->telem_addr))
		return -1;
	memcpy(o->telem_addr, s, alen);
	o->telem_addr[alen] = 0;
	o->telem_port = (uint16_t)port;
	return 0;
}

/* 1 when addr is a loopback address (127.0.0.0/8, ::1). */
static int is_loopback(const char *addr)
{
	struct in_addr a4;
	struct in6_addr a6;

	if (inet_pton(AF_INET, addr, &a4) == 1)
		return (ntohl(a4.s_addr) >> 24) == 127u;
	if (inet_pton(AF_INET6, addr, &a6) == 1)
		return IN6_IS_ADDR_LOOPBACK(&a6);
	return 0;
}

/* The token file (--telemetry-token): its bytes without trailing whitespace,
 * 16..TELEM_TOKEN_MAX of them. And the rule of who may connect: an address
 * other than loopback only with a token. 0, or 1 with the reason on stderr. */
int telemetry_check_access(struct servod_opts *o)
{
	if (o->telem_token_file) {
		unsigned char buf[TELEM_TOKEN_MAX + 2];
		int fd = open(o->telem_token_file, O_RDONLY | O_CLOEXEC);
		ssize_t n;
		struct stat st;

		if (fd < 0) {
			fprintf(stderr, "servod: --telemetry-token %s: %s\n", o->telem_token_file, strerror(errno));
			return 1;
		}
		if (fstat(fd, &st) == 0 && (st.st_mode & (S_IRWXG | S_IRWXO)))
			fprintf(stderr, "servod: warning: --telemetry-token %s is readable by group/others\n",
				o->telem_token_file);
		n = read(fd, buf, sizeof(buf));
		close(fd);
		while (n > 0 && (buf[n - 1] == '\n' || buf[n - 1] == '\r' || buf[n - 1] == ' ' || buf[n - 1] == '\t'))
			n--;
		if (n < 16 || n > (ssize_t)TELEM_TOKEN_MAX) {
			fprintf(stderr, "servod: --telemetry-token %s: the token must be 16..%u bytes\n",
				o->telem_token_file, TELEM_TOKEN_MAX);
			return 1;
		}
		memcpy(o->telem_token, buf, (size_t)n);
		o->telem_token_len = (uint32_t)n;
	}
	if (strcmp(o->telem, "off") && !o->telem_token_len && !is_loopback(o->telem_addr)) {
		fprintf(stderr, "servod: --telemetry %s is not a loopback address: it needs "
				"--telemetry-token FILE (docs/telemetry.md)\n", o->telem);
		return 1;
	}
	return 0;
}

/* The program runner's queue levels (its feeder thread) as a QUEUES event:
 * the layout's queue curves. */
static void push_queues(void *user, const uint32_t *level, const uint32_t *cap, unsigned n)
{
	struct servod *sd = user;
	struct telem_queue_level q[TELEM_MAX_QUEUES];

	if (n > TELEM_MAX_QUEUES)
		n = TELEM_MAX_QUEUES;
	for (unsigned i = 0; i < n; i++) {
		snprintf(q[i].name, sizeof(q[i].name), "%s", motion_queue_name(i));
		q[i].level = level[i];
		q[i].capacity = cap[i];
	}
	(void)telem_push_queues(&sd->telem, 0, q, n);	/* a full event queue counts the drop */
}

void telemetry_start(struct servod *sd)
{
	struct telem_cfg tc;
	int rc;

	if (!strcmp(sd->opt.telem, "off")) {
		logm(sd, "telemetry off");
		return;
	}
	telem_cfg_defaults(&tc);
	tc.listen_addr = sd->opt.telem_addr;
	tc.port = sd->opt.telem_port;
	tc.controller_id = sd->opt.id;
	tc.n_axes = sd->axes;
	tc.cycle_period_ns = sd->period_ns;
	tc.clock_hz = sd->opt.servo_clock_hz;
	tc.drain_interval_us = 10000u;	/* 100 wake-ups/s; the ring holds 4,096 cycles */
	tc.mlock = 1;
	tc.app_counters = cycle_stats_counters;
	tc.app_seq = cycle_stats_seq;
	tc.app_arg = &sd->pub;
	/* "param" requests (telemetry_serve) only from clients that presented
	 * the token: without one, any local process could connect */
	tc.requests = sd->opt.telem_token_len ? 1 : 0;
	tc.token = sd->opt.telem_token_len ? sd->opt.telem_token : NULL;
	tc.token_len = sd->opt.telem_token_len;
	rc = telem_init(&sd->telem, &tc);
	if (rc == 0)
		rc = telem_start(&sd->telem);
	if (rc) {
		logw(sd, "telemetry off: %s:%u: %s", sd->opt.telem_addr, sd->opt.telem_port, strerror(-rc));
		telem_destroy(&sd->telem);
		return;
	}
	sd->telem_on = 1;
	sd->prog.on_queues = push_queues;
	sd->prog.on_queues_user = sd;
	logm(sd, "telemetry on %s:%u (%u axes, ring %u cycles, %s)", sd->opt.telem_addr, telem_port(&sd->telem),
	     tc.n_axes, tc.ring_capacity, tc.token_len ? "token required" : "no token");
}

void telemetry_cycle(struct servod *sd, const struct cycle_wake *w, int rc, const struct amp_rx_info *rx,
		     const struct amp_cmd_axis *cmd, uint32_t n)
{
	const struct amp_fb_record *fb = &sd->amp.fb;
	uint32_t nfb = fb->n_axes < n ? fb->n_axes : n;	/* the axes the feedback covers */
	struct telem_cycle tr;

	if (!sd->telem_on)
		return;
	tr.cycle = sd->stats.cycles;
	tr.t_ns = w->t_ns;
	tr.servo_cycle = fb->cycle;
	tr.t_cycle = fb->t_cycle;
	tr.irq_latency = fb->irq_latency;
	tr.wake_latency_ns = w->lat_ns;
	/* AMP_RX_* and TELEM_X_* have the same values */
	tr.exchange = (rc == AMP_OK || rc == AMP_E_PEER_ERROR) ? rx->status : TELEM_X_NONE;
	tr.missed = rx->missed;
	tr.servo_status = fb->status;
	tr.result = rc;
	tr.n_axes = n;
	memcpy(tr.cmd, cmd, n * sizeof(cmd[0]));
	memcpy(tr.fb, fb->axis, nfb * sizeof(tr.fb[0]));
	memset(tr.fb + nfb, 0, (n - nfb) * sizeof(tr.fb[0]));
	telem_push_cycle(&sd->telem, &tr);
}

void telemetry_attach(struct servod *sd, int recovery, uint64_t stall_cycle, uint64_t cycle)
{
	if (!sd->telem_on)
		return;
	/* the attach as a GAP event (nothing lost: the cycles in between are
	 * on record with their exchange status): a recovery spans stall
	 * detection .. now */
	if (recovery)
		telem_push_gap(&sd->telem, 0, stall_cycle && stall_cycle <= cycle ? stall_cycle : cycle, cycle, 0,
			       TELEM_GAP_RECOVERY);
	else
		telem_push_gap(&sd->telem, 0, cycle, cycle, 0, TELEM_GAP_CONTROLLER_RESTART);
	/* the set just loaded into the servo */
	for (int i = 0; i < SP_P_COUNT; i++)
		if (param_desc[i].flags & SP_F_RESTORE)
			params_publish(sd, (uint32_t)i, sd->pset[i]);
}

/* The handlers' declarations (SERVOD_REQUEST, control.c). */
extern const struct servod_request __start_servod_requests[];
extern const struct servod_request __stop_servod_requests[];

/*
 * REQUEST frames of authenticated telemetry clients (docs/telemetry.md
 * "Requests"): "param list | get NAME | set NAME VALUE", run by the same
 * handler as ampctl's (range checks, the servo's answer checked, the file,
 * the PARAM event); anything else is refused. Main thread, like the
 * control socket, and bounded like it: at most TELEMETRY_REQUESTS_PER_PASS
 * per call (a parameter request may wait up to 200 ms for a hung servo),
 * so that the supervisor runs between two of them however many clients
 * keep in flight.
 */
int telemetry_serve(struct servod *sd)
{
	struct telem_request r;
	int served = 0;

	if (!sd->telem_on)
		return 0;
	while (served < TELEMETRY_REQUESTS_PER_PASS && telem_pop_request(&sd->telem, &r)) {
		char msg[512] = "", *argv[8], *save = 0, *tok;
		struct out o = { malloc(1024), 0, 1024 };
		int argc = 0, rc = SE_USAGE;

		served++;
		if (!o.buf) {
			telem_reply(&sd->telem, &r, SE_IO, "servod: out of memory", 21);
			return served;
		}
		for (tok = strtok_r(r.text, " \t\r\n", &save); tok && argc < 8; tok = strtok_r(0, " \t\r\n", &save))
			argv[argc++] = tok;
		snprintf(msg, sizeof(msg), "only \"param list | get NAME | set NAME VALUE\" is served here");
		if (argc && !strcmp(argv[0], "param"))
			for (const struct servod_request *q = __start_servod_requests; q < __stop_servod_requests; q++)
				if (!strcmp(q->name, "param"))
					rc = q->fn(sd, &o, argc, argv, msg, sizeof(msg));
		if (rc == SE_OK)
			telem_reply(&sd->telem, &r, 0, o.buf, o.len);
		else
			telem_reply(&sd->telem, &r, rc, msg, strlen(msg));
		free(o.buf);
	}
	return served;
}

void telemetry_stop(struct servod *sd)
{
	if (!sd->telem_on)
		return;
	/* after the cycle thread: drains the ring, final STATS, closes */
	telem_stop(&sd->telem);
	sd->telem_on = 0;
	telem_destroy(&sd->telem);
}
