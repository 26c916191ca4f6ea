// SPDX-License-Identifier: MIT
/*
 * servod's recovery on the host, continued (the rig: recovery_rig.h, and
 * test_servod_recovery.c for what it plays): an operator's stop through
 * remoteproc is final (issue 33, item 1), with and without the firmware's
 * STOPPING word, between two passes, during a recovery; and a driver
 * without report_crash (issue 35, item 3: the ZynqMP's upstream R5
 * driver): restart, parameter restore, latch and fault reset through
 * state alone, said once in the log instead of an error at each stall.
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

/* ---- (5) an operator's stop is final (issue 33, item 1) ----------------------- */

#ifndef AMP_SSTATE_STOPPING
/* the amp_lib before this change: the word a firmware would write */
#define AMP_SSTATE_STOPPING 0x53505453u
#endif

/* The firmware sees remoteproc's STOP (the Zynq-7000 driver's cooperative
 * stop): with its word (STOPPING, then no heartbeat) or without it (a
 * driver that powers the core down unasked). */
static void fw_stop_on_request(int with_word)
{
	pthread_mutex_lock(&g.fw);
	if (with_word)
		amp_servo_set_state(&g.s, AMP_SSTATE_STOPPING, 0);
	g.running = 0;
	pthread_mutex_unlock(&g.fw);
}

/* Cycles servod has run (its cycle thread), under its lock. */
static uint64_t servod_cycles(void)
{
	return stat_of(&g.sd->stats.cycles);
}

/* No pass of servod's main loop while the cycle thread runs n cycles: what
 * a supervisor blocked elsewhere (a sysfs write) lets pile up. */
static void cycles_without_passes(uint64_t n)
{
	uint64_t end = servod_cycles() + n;
	struct timespec ts = { 0, 200000 };

	for (int i = 0; i < 100000 && servod_cycles() < end; i++)
		nanosleep(&ts, 0);
}

/* The operator's "start" through remoteproc's state, and its attach. */
static void operator_start(uint64_t restores)
{
	wfile(g.dir, "state", "start");
	rproc_play();
	RUN_UNTIL(stat_of(&g.sd->stats.restores) == restores + 1, 10);
	CHECK_EQ(stat_of(&g.sd->stats.restores), restores + 1);
}

static void test_operator_stop_is_final(void)
{
	char msg[512], body[4096];
	uint64_t restores;
	unsigned starts;

	printf("servod recovery: the operator stops the firmware six times (limit 3), with and without its word\n");
	rig_up(3, 50, 0);
	for (int round = 0; round < 6; round++) {
		int with_word = round % 3 != 2;

		starts = g.starts;
		restores = stat_of(&g.sd->stats.restores);
		fw_stop_on_request(with_word);
		/*
		 * The sysfs write of "stop" blocks until the firmware parked
		 * (with the word) or the core is powered down: remoteproc says
		 * "running" meanwhile. The first three rounds make it last past
		 * wd_limit (20) cycles with the word; the third round, the
		 * stall is already seen when remoteproc says "offline", before
		 * servod's next pass (the state re-read before a report).
		 */
		if (with_word) {
			RUN_UNTIL(0, 0.05);	/* passes while the state says running */
			cycles_without_passes(3u * 20u);
			RUN_UNTIL(0, 0.05);
		} else {
			cycles_without_passes(3u * 20u);
		}
		fw_stop();
		g.power = 0;
		snprintf(g.kstate, sizeof(g.kstate), "offline");
		wfile(g.dir, "state", g.kstate);
		/* a new region at once: the operator's start follows without
		 * a pass in between (nothing of the stopped firmware's, such
		 * as a stall seen before the stop, may reach the new one) */
		RUN_UNTIL(g.sd->session.state == SESSION_OPEN, 5);
		printf("  round %d (%s): %u crash reports, %u starts, session %d\n", round,
		       with_word ? "STOPPING" : "no word", g.reports, g.starts - starts, g.sd->session.state);
		CHECK_EQ(g.reports, 0);
		CHECK_EQ(g.starts, starts);
		CHECK(!strcmp(g.kstate, "offline"));
		CHECK_EQ(g.sd->session.state, SESSION_OPEN);	/* a new region, waiting for a start */
		CHECK_EQ(stat_of(&g.sd->stats.recoveries), 0);
		CHECK_EQ(req("param get pos_kp", msg, sizeof(msg), body, sizeof(body)), SE_OFFLINE);
		operator_start(restores);
		/* the new firmware runs on: nothing left of the stop */
		RUN_UNTIL(0, 0.1);
		CHECK_EQ(g.reports, 0);
		CHECK_EQ(g.sd->session.state, SESSION_RUNNING);
	}
	CHECK(!latched());
	CHECK_EQ(stat_of(&g.sd->stats.latches), 0);
	/* and a firmware that hangs on its own is still recovered */
	restores = stat_of(&g.sd->stats.restores);
	fw_hang();
	RUN_UNTIL(stat_of(&g.sd->stats.restores) == restores + 1, 10);
	CHECK_EQ(g.reports, 1);
	CHECK_EQ(stat_of(&g.sd->stats.restores), restores + 1);
	CHECK_EQ(g.sd->session.state, SESSION_RUNNING);
	rig_down();
}

/* `echo stop; echo start` in quick succession: servod saw "offline" (its
 * session closed) and the firmware is running again before servod made a
 * new region; it attached to the region servod still has. servod takes it
 * back (before: "waiting until it is offline", for good, while the firmware
 * ran without its parameter set; the stop's stall had hidden that). */
static void test_stop_and_start_between_passes(void)
{
	uint64_t restores;

	printf("servod recovery: stop and start between two passes of the supervisor, ten times\n");
	rig_up(3, 50, 0);
	for (int round = 0; round < 10; round++) {
		restores = stat_of(&g.sd->stats.restores);
		fw_stop_on_request(1);
		fw_stop();
		g.power = 0;
		snprintf(g.kstate, sizeof(g.kstate), "offline");
		wfile(g.dir, "state", g.kstate);
		RUN_UNTIL(g.sd->session.state == SESSION_CLOSED, 5);
		CHECK_EQ(g.sd->session.state, SESSION_CLOSED);
		operator_start(restores);
		CHECK_EQ(g.sd->session.state, SESSION_RUNNING);
	}
	CHECK_EQ(g.reports, 0);
	CHECK(!latched());
	rig_down();
}

/* remoteproc's state as the driver sets it (no pass of servod's). */
static void remoteproc_says(const char *state)
{
	snprintf(g.kstate, sizeof(g.kstate), "%s", state);
	wfile(g.dir, "state", g.kstate);
}

/* The firmware's watchdog stalls plus the cycles that found its region
 * closed or re-initialised (each a safe stop on the board), and whether its
 * attach waits, under its lock. */
static uint32_t fw_safestop_cycles(int *attach_waits)
{
	uint32_t n;

	pthread_mutex_lock(&g.fw);
	n = g.wd_stalls + g.absent;
	*attach_waits = g.attach_retry;
	pthread_mutex_unlock(&g.fw);
	return n;
}

/* The operator's stop (with the firmware's word), remoteproc "offline"
 * (no pass of servod's yet); the restores and the epoch before it. */
static void stop_round(uint64_t *restores, uint32_t *epoch)
{
	*restores = stat_of(&g.sd->stats.restores);
	*epoch = g.sd->session.epoch;
	fw_stop_on_request(1);
	fw_stop();
	g.power = 0;
	remoteproc_says("offline");
}

/* `echo stop; echo start` where one pass of servod's saw "offline" (its
 * session closed) and the start completed before the next. servod closes
 * its region when the servo stops, so the new firmware waits for a new one
 * (before: it attached to the old region, where Linux no longer beat, and
 * its watchdog took it to its safe stop, fault LINUX_STALL, within
 * wd_limit cycles: on the board about 1 round in 12 at 4 kHz). Here it
 * runs 40 ms (wd_limit 20 cycles of about 0.5 ms) before servod's pass. */
static void test_start_before_the_pass_after_the_stop(void)
{
	struct timespec ms40 = { 0, 40000000 };
	uint64_t restores;
	uint32_t epoch, stalls;
	int waits;

	printf("servod recovery: a start between the pass that saw offline and the next, five times\n");
	rig_up(3, 50, 0);
	for (int round = 0; round < 5; round++) {
		stop_round(&restores, &epoch);
		RUN_UNTIL(g.sd->session.state == SESSION_CLOSED, 5);
		CHECK_EQ(g.sd->session.state, SESSION_CLOSED);
		stalls = fw_safestop_cycles(&waits);
		g.power = 1;
		remoteproc_says("running");
		fw_start();
		nanosleep(&ms40, 0);
		CHECK_EQ(fw_safestop_cycles(&waits), stalls);
		CHECK(waits);		/* the closed region refused it */
		RUN_UNTIL(stat_of(&g.sd->stats.restores) == restores + 1, 10);
		CHECK_EQ(stat_of(&g.sd->stats.restores), restores + 1);
		CHECK_EQ(g.sd->session.state, SESSION_RUNNING);
		CHECK_EQ(g.sd->session.epoch, epoch + 1u);	/* a new region */
		CHECK_EQ(fw_safestop_cycles(&waits), stalls);
		CHECK(!waits);
	}
	CHECK_EQ(g.reports, 0);
	CHECK(!latched());
	rig_down();
}

/* The same stop and start, but the new firmware attached before servod's
 * pass reads "offline": remoteproc says "running" only when the driver's
 * start op returns (the Zynq-7000's driver once it sees the firmware's
 * RUN!, written just before its first attach). Closing the region then
 * would take it from under the firmware (its safe stop, LINUX_GONE: 2 of
 * 150 rounds on the board). A new attach that beats is a start under way:
 * the session goes on, and the attach gets its parameter set once
 * remoteproc says "running". The same attach stopped for good, its line
 * still, is then an offline servo: the session closes. */
/* n rounds: the new firmware attached before the pass that reads
 * "offline"; the session goes on in the same region, no safe stop. */
static void attach_before_offline_rounds(int n)
{
	uint64_t restores;
	uint32_t epoch, stalls;
	int waits;

	for (int round = 0; round < n; round++) {
		stalls = fw_safestop_cycles(&waits);
		stop_round(&restores, &epoch);
		g.power = 1;
		fw_start();		/* the driver's start op has not returned */
		(void)fw_safestop_cycles(&waits);
		CHECK(!waits);
		RUN_UNTIL(0, 0.2);	/* passes, remoteproc "offline" */
		CHECK_EQ(g.sd->session.state, SESSION_RUNNING);
		remoteproc_says("running");
		RUN_UNTIL(stat_of(&g.sd->stats.restores) == restores + 1, 10);
		CHECK_EQ(stat_of(&g.sd->stats.restores), restores + 1);
		CHECK_EQ(g.sd->session.state, SESSION_RUNNING);
		CHECK_EQ(g.sd->session.epoch, epoch);	/* the same region */
		CHECK_EQ(fw_safestop_cycles(&waits), stalls);
		CHECK(!waits);
	}
}

static void test_attached_before_the_pass_that_reads_offline(void)
{
	uint64_t restores;
	uint32_t epoch;

	printf("servod recovery: the new firmware attached before the pass that reads offline, five times\n");
	rig_up(3, 50, 0);
	attach_before_offline_rounds(5);	/* attaches 2..6 */
	/* attached, then stopped (no word: powered down) before "running" */
	stop_round(&restores, &epoch);
	fw_start();				/* attach 7 */
	RUN_UNTIL(0, 0.05);
	fw_stop();
	RUN_UNTIL(g.sd->session.state == SESSION_CLOSED, 5);
	CHECK_EQ(g.sd->session.state, SESSION_CLOSED);
	/* a new region, and later the same attach counts in it: an attach
	 * of the region before is not this one's (2 s on, it would be taken
	 * for a start under way for too long, its region closed under it) */
	g.power = 1;
	remoteproc_says("running");
	fw_start();
	RUN_UNTIL(stat_of(&g.sd->stats.restores) == restores + 1, 10);
	CHECK_EQ(g.sd->session.epoch, epoch + 1u);
	for (int i = 0; i < 5; i++) {		/* attaches 2..6, remoteproc "running" */
		restores = stat_of(&g.sd->stats.restores);
		fw_stop_on_request(1);
		fw_stop();
		fw_start();
		RUN_UNTIL(stat_of(&g.sd->stats.restores) == restores + 1, 10);
		CHECK_EQ(stat_of(&g.sd->stats.restores), restores + 1);
	}
	RUN_UNTIL(0, 2.1);
	attach_before_offline_rounds(1);	/* attach 7 */
	CHECK_EQ(g.reports, 0);
	CHECK(!latched());
	rig_down();
}

/* The operator stops a firmware servod restarted, once it attached, before
 * its parameter set is loaded: the recovery ends there. */
static void test_operator_stop_during_recovery(void)
{
	unsigned starts;

	printf("servod recovery: the operator stops the restarted firmware before its parameter set\n");
	rig_up(3, 50, 0);
	fw_hang();
	RUN_UNTIL(g.reports == 1 && g.starts == 2, 10);
	CHECK_EQ(g.starts, 2);
	/* the restarted firmware attached; the supervisor has not run since */
	fw_stop_on_request(1);
	fw_stop();
	g.power = 0;
	snprintf(g.kstate, sizeof(g.kstate), "offline");
	wfile(g.dir, "state", g.kstate);
	starts = g.starts;
	RUN_UNTIL(g.sd->session.state == SESSION_OPEN, 5);
	RUN_UNTIL(0, 0.3);
	printf("  %u starts after the stop, session %d\n", g.starts - starts, g.sd->session.state);
	CHECK_EQ(g.starts, starts);
	CHECK(!strcmp(g.kstate, "offline"));
	CHECK_EQ(g.sd->session.state, SESSION_OPEN);
	CHECK_EQ(g.sd->recovery.phase, RESTART_NONE);
	CHECK(!latched());
	rig_down();
}

/* ---- (6) a driver without report_crash (the ZynqMP's upstream R5 driver) --------- */

/* servod's log (its stderr) from here into a file, until log_end(). */
static int log_fd_saved = -1;
static char log_path[64];

static void log_begin(void)
{
	int fd;

	snprintf(log_path, sizeof(log_path), "/tmp/servod-rlog.XXXXXX");
	fd = mkstemp(log_path);
	CHECK(fd >= 0);
	fflush(stderr);
	log_fd_saved = dup(2);
	dup2(fd, 2);
	close(fd);
}

/* The log captured since log_begin() (also echoed to stdout), in buf. */
static void log_end(char *buf, size_t n)
{
	FILE *f;
	size_t got = 0;

	fflush(stderr);
	dup2(log_fd_saved, 2);
	close(log_fd_saved);
	f = fopen(log_path, "r");
	if (f) {
		got = fread(buf, 1, n - 1, f);
		fclose(f);
	}
	buf[got] = 0;
	unlink(log_path);
	fputs(buf, stdout);
}

static unsigned count_of(const char *hay, const char *needle)
{
	unsigned c = 0;

	for (const char *p = strstr(hay, needle); p; p = strstr(p + 1, needle))
		c++;
	return c;
}

static void test_driver_without_report_crash(void)
{
	static char log[65536];
	char msg[512], body[4096], rec[32], p[160];
	uint64_t restores;
	uint32_t kp;

	printf("servod recovery: a driver without report_crash (the upstream R5 driver)\n");
	log_begin();
	rig_upstream = 1;
	rig_up(3, 50, 0);
	rig_upstream = 0;
	CHECK_EQ(g.sd->rproc.report_crash, 0);
	/* a parameter set by the operator before the hang */
	CHECK_EQ(req("param set pos_kp 61.5", msg, sizeof(msg), body, sizeof(body)), SE_OK);
	kp = sp_word_from_f32(61.5f);
	CHECK_EQ(g.val[SP_P_pos_kp], kp);
	/* the firmware hangs: stopped and started through state, the restarted
	 * firmware (its defaults: nothing of the old one's values) gets the set */
	restores = stat_of(&g.sd->stats.restores);
	fw_hang();
	pthread_mutex_lock(&g.fw);
	g.val[SP_P_pos_kp] = 0;
	pthread_mutex_unlock(&g.fw);
	RUN_UNTIL(stat_of(&g.sd->stats.restores) == restores + 1, 10);
	CHECK_EQ(stat_of(&g.sd->stats.restores), restores + 1);
	CHECK_EQ(stat_of(&g.sd->stats.recoveries), 1);
	CHECK_EQ(g.starts, 2);
	CHECK_EQ(g.stops, 1);
	CHECK_EQ(g.reports, 0);
	CHECK(!strcmp(g.kstate, "running"));
	CHECK_EQ(g.sd->session.state, SESSION_RUNNING);
	pthread_mutex_lock(&g.fw);
	CHECK_EQ(g.val[SP_P_pos_kp], kp);
	pthread_mutex_unlock(&g.fw);
	/* servod wrote no report_crash (none made) and left recovery as the
	 * driver set it */
	snprintf(p, sizeof(p), "%s/device/report_crash", g.dir);
	CHECK(access(p, F_OK) != 0);
	rfile(g.dir, "recovery", rec, sizeof(rec));
	CHECK(!strcmp(rec, "disabled"));
	/* fails after every attach: the window's limit (3, one used) latches */
	pthread_mutex_lock(&g.fw);
	g.hang_after_attach = 1;
	pthread_mutex_unlock(&g.fw);
	RUN_UNTIL(latched() || g.starts >= 8, 30);
	CHECK(latched());
	CHECK_EQ(stat_of(&g.sd->stats.recoveries), 3);
	CHECK_EQ(g.starts, 1 + 3);
	CHECK(!strcmp(g.kstate, "offline"));
	CHECK_EQ(g.power, 0);
	CHECK_EQ(req("status", msg, sizeof(msg), body, sizeof(body)), SE_OFFLINE);
	CHECK(body_has(body, "latched_why=servo stalled (heartbeat still for 20 cycles); 3 restarts within 60 s"));
	/* the operator's reset: back, with the parameter set */
	pthread_mutex_lock(&g.fw);
	g.hang_after_attach = 0;
	g.val[SP_P_pos_kp] = 0;
	pthread_mutex_unlock(&g.fw);
	restores = stat_of(&g.sd->stats.restores);
	CHECK_EQ(req("fault reset", msg, sizeof(msg), body, sizeof(body)), SE_OK);
	RUN_UNTIL(stat_of(&g.sd->stats.restores) == restores + 1, 10);
	CHECK_EQ(stat_of(&g.sd->stats.restores), restores + 1);
	CHECK_EQ(g.sd->session.state, SESSION_RUNNING);
	pthread_mutex_lock(&g.fw);
	CHECK_EQ(g.val[SP_P_pos_kp], kp);
	pthread_mutex_unlock(&g.fw);
	CHECK_EQ(g.reports, 0);
	rig_down();
	log_end(log, sizeof(log));
	/* said once what it does instead; no error at each of the 3 stalls */
	CHECK_EQ(count_of(log, "no device/report_crash"), 1);
	CHECK_EQ(count_of(log, "remoteproc's own recovery is disabled"), 1);
	CHECK_EQ(count_of(log, "restarting the firmware (servod's record"), 3);
	CHECK_EQ(count_of(log, "reporting a crash"), 0);
	CHECK_EQ(count_of(log, "No such file"), 0);
	CHECK_EQ(count_of(log, "all the same"), 0);
}

int main(void)
{
	setvbuf(stdout, 0, _IOLBF, 0);
	test_operator_stop_is_final();
	test_operator_stop_during_recovery();
	test_stop_and_start_between_passes();
	test_start_before_the_pass_after_the_stop();
	test_attached_before_the_pass_that_reads_offline();
	test_driver_without_report_crash();
	return rig_summary("servod recovery (stop)");
}
