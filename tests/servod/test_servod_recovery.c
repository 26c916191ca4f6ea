// SPDX-License-Identifier: MIT
/*
 * Issue 20, items 2 and 3, on the host: servod's own supervisor, cycle
 * thread, parameter service and telemetry server (every servod file but
 * main.c), against
 *
 *   - a servo on a host buffer standing in for OCM: amp_lib's servo side,
 *     one cycle per tick of a ticker thread that also delivers servod's
 *     cycle interrupt (a datagram socket standing in for the UIO device; in
 *     lock step, so that only a hung servo stalls), answering the mailbox;
 *     it can hang (heartbeat and mailbox stop, as `ampctl debug hang`),
 *     hang after each attach once its parameter set is loaded, never
 *     start, or attach inside servod's cycle (between amp_linux_cycle()'s
 *     watchdog and what servod does with its verdict: telemetry_cycle(),
 *     wrapped by the linker, --wrap, attaches it there);
 *   - remoteproc in sysfs played by the test between two passes of the main
 *     loop: a directory with state, recovery and device/report_crash (or,
 *     as the upstream xlnx_r5_remoteproc, no report_crash and recovery
 *     disabled by the driver), the
 *     kernel's rules applied to what servod wrote (report_crash with
 *     recovery enabled stops and starts the firmware, and a start that fails
 *     there leaves it offline with its power reference held: a later
 *     "start" does nothing; with recovery disabled the state is "crashed";
 *     "stop" from running or crashed, "start" from offline).
 *
 * Each case ran against the servod before this change and failed there (it
 * restarted a firmware that fails after every attach forever, never retried
 * a failed restart, and served pipelined telemetry requests while a stall
 * waited to be reported). No assertion on host time other than lower
 * bounds (a retry comes no earlier than its backoff).
 */
#define _GNU_SOURCE
#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include "check.h"
#include "context.h"
#include "recovery_rig.h"

/* ---- the bounds themselves (recovery.c) -------------------------------------- */

static void test_bounds(void)
{
#ifdef RECOVERY_CFG_DEFAULT
	const uint64_t s = 1000000000ull;
	struct recovery_cfg c = RECOVERY_CFG_DEFAULT;
	struct recovery r;
	static const uint32_t backoff_s[] = { 1, 2, 4, 8, 16, 30, 30, 30 };

	memset(&r, 0, sizeof(r));
	CHECK_EQ(c.limit, 3);
	CHECK_EQ(c.window_ms, 60000);
	for (uint64_t i = 0; i < 3; i++) {
		CHECK(recovery_may_restart(&r, &c, (10 + i) * s));
		recovery_note_restart(&r, (10 + i) * s);
	}
	CHECK_EQ(recovery_in_window(&r, &c, 13 * s), 3);
	CHECK(!recovery_may_restart(&r, &c, 13 * s));	/* a fourth within 60 s */
	CHECK(!recovery_may_restart(&r, &c, 69 * s));
	CHECK(recovery_may_restart(&r, &c, 70 * s));	/* the first one left the window */
	CHECK_EQ(recovery_in_window(&r, &c, 72 * s), 0);
	for (uint32_t n = 1; n <= 8; n++)
		CHECK_EQ(recovery_backoff_ns(&c, n), backoff_s[n - 1] * s);
	/* no limit: never latched; the ring forgets the oldest */
	c.limit = 0;
	for (uint64_t i = 0; i < 100; i++)
		recovery_note_restart(&r, (100 + i) * s / 100);
	CHECK(recovery_may_restart(&r, &c, 2 * s));
	c.limit = RECOVERY_HISTORY_MAX;
	CHECK_EQ(recovery_in_window(&r, &c, 2 * s), RECOVERY_HISTORY_MAX);
	CHECK(!recovery_may_restart(&r, &c, 2 * s));
	r.kernel_recovery_off = 1;
	recovery_clear(&r);
	CHECK_EQ(r.nhist, 0);
	CHECK_EQ(r.kernel_recovery_off, 1);
	CHECK(recovery_may_restart(&r, &c, 2 * s));
	/* the session: latched from any open state, only the reset leaves it */
	CHECK_EQ(session_next(SESSION_RUNNING, SEV_LATCHED), SESSION_FAULT);
	CHECK_EQ(session_next(SESSION_RECOVERING, SEV_LATCHED), SESSION_FAULT);
	CHECK_EQ(session_next(SESSION_OPEN, SEV_LATCHED), SESSION_FAULT);
	CHECK_EQ(session_next(SESSION_CLOSED, SEV_LATCHED), SESSION_CLOSED);
	for (int ev = SEV_REGION_READY; ev <= SEV_LATCHED; ev++)
		CHECK_EQ(session_next(SESSION_FAULT, (enum session_event)ev), SESSION_FAULT);
	CHECK_EQ(session_next(SESSION_FAULT, SEV_RESET), SESSION_RECOVERING);
	CHECK_EQ(session_next(SESSION_RUNNING, SEV_RESET), SESSION_RUNNING);
	{
		struct session ss = { .state = SESSION_FAULT };

		CHECK(!session_open(&ss) && session_has_region(&ss) && session_latched(&ss));
	}
#else
	CHECK(!"servod has no bounds on recovery (recovery.h)");
#endif
}

/* ---- (1) a firmware that fails after every attach: latched after K ------------ */

static void test_fails_after_every_attach(void)
{
	char msg[512], body[4096];
	unsigned starts;
	uint64_t restores;

	printf("servod recovery: a firmware that hangs after every attach\n");
	rig_up(3, 50, 0);
	pthread_mutex_lock(&g.fw);
	g.hang_after_attach = 1;
	pthread_mutex_unlock(&g.fw);
	RUN_UNTIL(latched() || g.reports >= 6, 30);
	printf("  %u crash reports, %u starts, %llu recoveries\n", g.reports, g.starts,
	       (unsigned long long)stat_of(&g.sd->stats.recoveries));
	/* three restarts, then the fourth stall latches the fault */
	CHECK_EQ(stat_of(&g.sd->stats.recoveries), 3);
	CHECK_EQ(g.reports, 3);
	CHECK_EQ(g.starts, 1 + 3);
	/* the firmware stopped, nothing powered */
	CHECK(!strcmp(g.kstate, "offline"));
	CHECK_EQ(g.power, 0);
	CHECK_EQ(g.running, 0);
	/* `ampctl status` says why: exit 3 and the reason */
	CHECK_EQ(req("status", msg, sizeof(msg), body, sizeof(body)), SE_OFFLINE);
	CHECK(body_has(msg, "fault latched (servo stalled (heartbeat still for 20 cycles); "
			    "3 restarts within 60 s (limit 3))"));
	CHECK(body_has(msg, "ampctl fault reset"));
	CHECK(body_has(body, "session=fault"));
	CHECK(body_has(body, "latched=1"));
	CHECK(body_has(body, "firmware_stopped=1"));
	CHECK(body_has(body, "latched_why=servo stalled (heartbeat still for 20 cycles); 3 restarts within 60 s"));
	/* a parameter request is refused at once, not after a mailbox timeout */
	CHECK_EQ(req("param get pos_kp", msg, sizeof(msg), body, sizeof(body)), SE_OFFLINE);
	/* it stays so: nothing restarted while latched */
	starts = g.starts;
	RUN_UNTIL(0, 0.5);
	CHECK_EQ(g.starts, starts);
	CHECK_EQ(g.reports, 3);
#ifdef RECOVERY_CFG_DEFAULT
	CHECK_EQ(stat_of(&g.sd->stats.latches), 1);
	CHECK(session_latched(&g.sd->session));
#endif
	/* the operator's reset brings it back (a firmware that runs now) */
	pthread_mutex_lock(&g.fw);
	g.hang_after_attach = 0;
	pthread_mutex_unlock(&g.fw);
	restores = stat_of(&g.sd->stats.restores);
	CHECK_EQ(req("fault reset", msg, sizeof(msg), body, sizeof(body)), SE_OK);
	CHECK(body_has(body, "fault reset: restarting the servo"));
	RUN_UNTIL(stat_of(&g.sd->stats.restores) == restores + 1, 10);
	CHECK_EQ(stat_of(&g.sd->stats.restores), restores + 1);
	CHECK(!strcmp(g.kstate, "running"));
	CHECK_EQ(g.sd->session.state, SESSION_RUNNING);
	CHECK_EQ(req("status", msg, sizeof(msg), body, sizeof(body)), SE_OK);
	CHECK(body_has(body, "latched=0"));
	CHECK(body_has(body, "session=open"));
	/* and it runs: no stall, no restart */
	RUN_UNTIL(0, 0.3);
	CHECK_EQ(g.reports, 3);
	CHECK_EQ(g.sd->session.state, SESSION_RUNNING);
	rig_down();
}

/* ---- (2) a restart that fails is retried with backoff and reported ------------- */

static void test_failed_restart_retried(void)
{
	char msg[512], body[4096], rec[32];
	unsigned base;
	uint64_t restores;

	printf("servod recovery: the restarted firmware does not start twice, then does\n");
	rig_up(3, 100, 0);
	restores = stat_of(&g.sd->stats.restores);
	base = g.starts;	/* the index of the first restart's start */
	g.start_fails = 1;
	fw_hang();
	RUN_UNTIL(g.fails >= 2, 10);
	g.start_fails = 0;	/* the next start works */
	RUN_UNTIL(stat_of(&g.sd->stats.restores) == restores + 1, 10);
	printf("  %u starts (%u failed), %u crash reports\n", g.starts, g.fails, g.reports);
	CHECK_EQ(g.reports, 1);
	CHECK_EQ(g.fails, 2);
	CHECK_EQ(g.starts, base + 3);
	CHECK_EQ(stat_of(&g.sd->stats.restores), restores + 1);
	CHECK_EQ(g.sd->session.state, SESSION_RUNNING);
	/* each retry came no earlier than its backoff (100 ms, then 200 ms) */
	if (g.starts == base + 3 && g.fails == 2) {
		uint64_t gap1 = g.start_ns[base + 1] - g.fail_ns[0], gap2 = g.start_ns[base + 2] - g.fail_ns[1];

		printf("  retries %.0f ms and %.0f ms after the failed starts\n", gap1 / 1e6, gap2 / 1e6);
		CHECK(gap1 >= 100000000u);
		CHECK(gap2 >= 200000000u);
	}
	/* servod restarted it itself: remoteproc's own recovery is off */
	rfile(g.dir, "recovery", rec, sizeof(rec));
	CHECK(!strcmp(rec, "disabled"));
	CHECK_EQ(g.kernel_recoveries, 0);
	/* reported: counters, the last failure in `ampctl status` */
	CHECK_EQ(stat_of(&g.sd->stats.recoveries), 1);
#ifdef RECOVERY_CFG_DEFAULT
	CHECK_EQ(stat_of(&g.sd->stats.recovery_failures), 2);
	CHECK_EQ(stat_of(&g.sd->stats.recovery_retries), 2);
	CHECK_EQ(stat_of(&g.sd->stats.latches), 0);
#endif
	CHECK_EQ(req("status", msg, sizeof(msg), body, sizeof(body)), SE_OK);
	CHECK(body_has(body, "last_restart_failure=remoteproc offline after the start"));
	CHECK(body_has(body, "recovery=none"));
	CHECK(body_has(body, "latched=0"));
	CHECK_EQ(req("stats", msg, sizeof(msg), body, sizeof(body)), SE_OK);
	CHECK(body_has(body, "linux.recovery_failures=2\n"));
	CHECK(body_has(body, "linux.recovery_retries=2\n"));
	rig_down();
}

/* A restart that keeps failing: retried within the limit, then latched. */
static void test_failing_restart_latches(void)
{
	char msg[512], body[4096];
	uint64_t restores;

	printf("servod recovery: the restarted firmware never starts\n");
	rig_up(3, 50, 0);
	g.start_fails = 1;
	fw_hang();
	RUN_UNTIL(latched() || g.fails >= 5, 10);
	(void)req("status", msg, sizeof(msg), body, sizeof(body));
	printf("  %u starts failed\n", g.fails);
	CHECK_EQ(g.fails, 3);
	CHECK(body_has(body, "latched=1"));
	CHECK(body_has(body, "latched_why=restart 3 failed (remoteproc offline after the start); "
			     "3 restarts within 60 s"));
	CHECK(body_has(msg, "fault latched"));
#ifdef RECOVERY_CFG_DEFAULT
	CHECK_EQ(stat_of(&g.sd->stats.recovery_failures), 3);
	CHECK_EQ(stat_of(&g.sd->stats.recovery_retries), 2);
#endif
	/* the image fixed, the operator resets: back */
	g.start_fails = 0;
	restores = stat_of(&g.sd->stats.restores);
	CHECK_EQ(req("fault reset", msg, sizeof(msg), body, sizeof(body)), SE_OK);
	RUN_UNTIL(stat_of(&g.sd->stats.restores) == restores + 1, 10);
	CHECK_EQ(stat_of(&g.sd->stats.restores), restores + 1);
	CHECK_EQ(g.sd->session.state, SESSION_RUNNING);
	rig_down();
}

/* ---- (3) pipelined telemetry requests never keep the supervisor out ----------- */

#define CLIENT_REQUESTS 24u

static atomic_int client_stop;

static int send_frame(int fd, uint16_t type, const void *payload, uint32_t len)
{
	unsigned char b[8 + 4 + TELEM_REQ_MAX];

	memcpy(b, &type, 2);
	memset(b + 2, 0, 2);
	memcpy(b + 4, &len, 4);
	memcpy(b + 8, payload, len);
	return send(fd, b, 8u + len, MSG_NOSIGNAL) == (ssize_t)(8u + len) ? 0 : -1;
}

static int send_request(int fd, uint32_t id)
{
	unsigned char p[64];
	const char *text = "param get pos_kp";

	memcpy(p, &id, 4);
	memcpy(p + 4, text, strlen(text));
	return send_frame(fd, TELEM_MSG_REQUEST, p, 4u + (uint32_t)strlen(text));
}

/* Keeps two requests in flight (the most a client may) until it has
 * CLIENT_REQUESTS answers; hangs the firmware at the second answer. */
static void *client(void *arg)
{
	struct sockaddr_in a = { .sin_family = AF_INET };
	static unsigned char buf[1 << 16];
	size_t have = 0;
	uint32_t sent = 0;
	int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0), hello = 0;

	(void)arg;
	a.sin_port = htons(telem_port(&g.sd->telem));
	a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
	if (fd < 0 || connect(fd, (struct sockaddr *)&a, sizeof(a)) ||
	    send_frame(fd, TELEM_MSG_AUTH, TOKEN, sizeof(TOKEN) - 1)) {
		printf("  client: cannot connect: %s\n", strerror(errno));
		if (fd >= 0)
			close(fd);
		return 0;
	}
	while (!atomic_load(&client_stop) && atomic_load(&g.replies) < CLIENT_REQUESTS) {
		struct pollfd p = { fd, POLLIN, 0 };
		ssize_t r;
		size_t off = 0;

		if (poll(&p, 1, 100) != 1)
			continue;
		r = recv(fd, buf + have, sizeof(buf) - have, 0);
		if (r <= 0)
			break;
		have += (size_t)r;
		while (have - off >= 8) {
			uint16_t type;
			uint32_t len;

			memcpy(&type, buf + off, 2);
			memcpy(&len, buf + off + 4, 4);
			if (len > sizeof(buf) - 8) {
				printf("  client: bad frame length %u\n", len);
				goto out;
			}
			if (have - off < 8u + len)
				break;
			if (type == TELEM_MSG_HELLO && !hello) {
				hello = 1;	/* authenticated: two requests out */
				for (; sent < 2; sent++)
					(void)send_request(fd, sent + 1);
			} else if (type == TELEM_MSG_REPLY) {
				/* the firmware hangs once two answers came */
				if (atomic_fetch_add(&g.replies, 1) + 1u == 2u)
					fw_hang();
				if (sent < CLIENT_REQUESTS && !send_request(fd, sent + 1))
					sent++;
			}
			off += 8u + len;
		}
		memmove(buf, buf + off, have - off);
		have -= off;
	}
out:
	close(fd);
	return 0;
}

static void test_requests_do_not_starve(void)
{
	pthread_t th;
	unsigned at_report;
	uint64_t restores;

	printf("servod recovery: a telemetry client keeps two requests in flight while the firmware hangs\n");
	rig_up(3, 50, 1);
	atomic_store(&client_stop, 0);
	CHECK_EQ(pthread_create(&th, 0, client, 0), 0);
	restores = stat_of(&g.sd->stats.restores);
	RUN_UNTIL(g.reports >= 1, 30);
	at_report = atomic_load(&g.replies);
	printf("  stall seen after %u answers, reported after %u (of %u)\n", atomic_load(&g.replies_at_stall),
	       at_report, CLIENT_REQUESTS);
	CHECK(atomic_load(&g.stall_seen));
	CHECK_EQ(g.reports, 1);
	/* between the stall and its report: the request being served and at
	 * most one more (a pass serves one), plus an answer on its way */
	CHECK(at_report - atomic_load(&g.replies_at_stall) <= 3u);
	CHECK(at_report < CLIENT_REQUESTS);
	/* and the recovery comes while the client keeps asking */
	RUN_UNTIL(stat_of(&g.sd->stats.restores) == restores + 1, 10);
	CHECK_EQ(stat_of(&g.sd->stats.restores), restores + 1);
	CHECK_EQ(g.sd->session.state, SESSION_RUNNING);
	atomic_store(&client_stop, 1);
	pthread_join(th, 0);
	rig_down();
}

/* ---- (4) the restart's attach inside the cycle that judged the old firmware ---- */

static void test_attach_inside_a_stalled_cycle(void)
{
	uint64_t restores, failures;

	printf("servod recovery: the restarted firmware attaches inside the cycle that judged the old one stalled\n");
	rig_up(3, 50, 0);
	restores = stat_of(&g.sd->stats.restores);
	failures = stat_of(&g.sd->stats.recovery_failures);
	pthread_mutex_lock(&g.fw);
	g.attach_in_cycle = 1;
	pthread_mutex_unlock(&g.fw);
	fw_hang();
	RUN_UNTIL(stat_of(&g.sd->stats.restores) == restores + 1 || latched(), 10);
	printf("  %u attached in a stalled cycle, %u crash reports, %llu failed restarts\n",
	       atomic_load(&g.attached_in_cycle), g.reports,
	       (unsigned long long)(stat_of(&g.sd->stats.recovery_failures) - failures));
	CHECK(atomic_load(&g.attached_in_cycle) >= 1);
	/* the old firmware's stall is not the new one's: one report, the
	 * restart good, the new attach given its parameter set */
	CHECK_EQ(g.reports, 1);
	CHECK_EQ(stat_of(&g.sd->stats.recovery_failures), failures);
	CHECK_EQ(stat_of(&g.sd->stats.restores), restores + 1);
	CHECK_EQ(g.sd->session.state, SESSION_RUNNING);
	/* and the new firmware's own stall is reported and recovered */
	pthread_mutex_lock(&g.fw);
	g.attach_in_cycle = 0;
	pthread_mutex_unlock(&g.fw);
	fw_hang();
	RUN_UNTIL(stat_of(&g.sd->stats.restores) == restores + 2 || latched(), 10);
	CHECK_EQ(g.reports, 2);
	CHECK_EQ(stat_of(&g.sd->stats.restores), restores + 2);
	CHECK_EQ(g.sd->session.state, SESSION_RUNNING);
	rig_down();
}

int main(void)
{
	setvbuf(stdout, 0, _IOLBF, 0);
	test_bounds();
	test_attach_inside_a_stalled_cycle();
	test_fails_after_every_attach();
	test_failed_restart_retried();
	test_failing_restart_latches();
	test_requests_do_not_starve();
	return rig_summary("servod recovery");
}
