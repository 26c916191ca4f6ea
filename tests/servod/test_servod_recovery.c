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

extern const struct servod_request __start_servod_requests[];
extern const struct servod_request __stop_servod_requests[];

static const char TOKEN[] = "0123456789abcdef0123456789abcdef";

static _Alignas(64) uint8_t ocm[AMP_OCM_SIZE];
static _Alignas(64) uint8_t ttc_regs[4096];
static atomic_int quit;

/* ---- the rig ------------------------------------------------------------------ */

struct rig {
	struct servod *sd;
	char dir[64];			/* the remoteproc instance's directory */
	char pfile[64];			/* servod's parameter file */
	int irq[2];			/* [0] servod's "UIO" fd, [1] the ticker's */
	pthread_t cycle_th, tick_th;
	atomic_int stop_ticker;
	/* the firmware (under fw) */
	pthread_mutex_t fw;
	struct amp_servo s;
	int running, hang, hang_after_attach;
	int attach_in_cycle;		/* a start leaves the attach to the next stalled cycle */
	atomic_int attach_due;		/* started: the cycle attaches it */
	atomic_uint attached_in_cycle;
	uint32_t cycles, sets;		/* since its attach */
	uint32_t val[SP_P_COUNT];
	/* remoteproc (test thread) */
	char kstate[16];
	int power, start_fails;
	unsigned starts, stops, reports, kernel_recoveries;
	uint64_t start_ns[16], fail_ns[16];	/* each start, each failed start */
	unsigned fails;
	/* the telemetry client */
	atomic_uint replies, replies_at_stall;
	atomic_int stall_seen;
};

static struct rig g;
/* the next rig_up plays a driver without device/report_crash whose own
 * recovery is disabled at probe (the upstream xlnx_r5_remoteproc) */
static int rig_upstream;

static void wfile(const char *dir, const char *name, const char *text)
{
	char p[160];
	int fd;

	snprintf(p, sizeof(p), "%s/%s", dir, name);
	fd = open(p, O_WRONLY | O_CREAT | O_TRUNC, 0644);
	CHECK(fd >= 0);
	if (fd >= 0) {
		CHECK_EQ(write(fd, text, strlen(text)), (ssize_t)strlen(text));
		close(fd);
	}
}

static void rfile(const char *dir, const char *name, char *buf, size_t n)
{
	char p[160];

	snprintf(p, sizeof(p), "%s/%s", dir, name);
	if (sysfs_read(p, buf, n))
		buf[0] = 0;
}

/* The firmware attaches (a start) / stops (parked: its line left as it is). */
static void fw_start(void)
{
	pthread_mutex_lock(&g.fw);
	CHECK_EQ(amp_servo_attach(&g.s, ocm, sizeof(ocm)), AMP_OK);
	g.running = 1;
	g.hang = 0;
	g.cycles = 0;
	g.sets = 0;
	pthread_mutex_unlock(&g.fw);
}

static void fw_stop(void)
{
	pthread_mutex_lock(&g.fw);
	g.running = 0;
	pthread_mutex_unlock(&g.fw);
}

static void fw_hang(void)
{
	pthread_mutex_lock(&g.fw);
	g.hang = 1;
	pthread_mutex_unlock(&g.fw);
}

static uint32_t payload_word(const struct amp_mbox_req *r, uint32_t i)
{
	const uint8_t *p = r->payload + 4u * i;

	return i < r->length / 4u ? (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 |
				    (uint32_t)p[3] << 24 : 0u;
}

/* The firmware's mailbox: parameters kept as they come, a status of zeros. */
static void fw_serve(void)
{
	struct amp_mbox_req r;
	uint32_t out[(sizeof(struct sp_status) + 3u) / 4u];

	if (amp_servo_mbox_poll(&g.s, &r) != 1)
		return;
	memset(out, 0, sizeof(out));
	switch (r.command) {
	case SP_CMD_PARAM_SET_MANY:
		for (uint32_t i = 0; i < payload_word(&r, 0); i++)
			if (payload_word(&r, 1u + 2u * i) < SP_P_COUNT)
				g.val[payload_word(&r, 1u + 2u * i)] = payload_word(&r, 2u + 2u * i);
		out[0] = payload_word(&r, 0);
		g.sets++;
		(void)amp_servo_mbox_respond(&g.s, 0, out, 4);
		return;
	case SP_CMD_PARAM_GET:
	case SP_CMD_PARAM_SET:
		out[0] = payload_word(&r, 0);
		if (out[0] >= SP_P_COUNT) {
			(void)amp_servo_mbox_respond(&g.s, SP_E_ID, 0, 0);
			return;
		}
		if (r.command == SP_CMD_PARAM_SET)
			g.val[out[0]] = payload_word(&r, 1);
		out[1] = g.val[out[0]];
		(void)amp_servo_mbox_respond(&g.s, 0, out, 8);
		return;
	case SP_CMD_STATUS:
		(void)amp_servo_mbox_respond(&g.s, 0, out, sizeof(struct sp_status));
		return;
	default:
		(void)amp_servo_mbox_respond(&g.s, SP_E_CMD, 0, 0);
	}
}

/* Every ~0.5 ms: the firmware's cycle (unless stopped or hung), then
 * servod's cycle interrupt, then the wait for servod to take it. */
static void *ticker(void *arg)
{
	uint32_t count = 0, ack;
	struct amp_fb_axis fb[4];
	uint64_t stalls0;

	(void)arg;
	memset(fb, 0, sizeof(fb));
	pthread_mutex_lock(&g.sd->lock);
	stalls0 = g.sd->stats.stalls;
	pthread_mutex_unlock(&g.sd->lock);
	while (!atomic_load(&g.stop_ticker)) {
		struct pollfd p = { g.irq[1], POLLIN, 0 };
		struct timespec ts = { 0, 500000 };
		struct amp_rx_info rx;

		pthread_mutex_lock(&g.fw);
		if (g.running && !g.hang) {
			(void)amp_servo_cycle_rx(&g.s, 0, &rx);
			(void)amp_servo_cycle_tx(&g.s, fb, 4, 0, 0);
			fw_serve();
			g.cycles++;
			if (g.hang_after_attach && g.sets && g.cycles > 30)
				g.hang = 1;
		}
		pthread_mutex_unlock(&g.fw);
		count++;
		if (send(g.irq[1], &count, 4, 0) != 4)
			break;
		if (poll(&p, 1, 200) == 1)
			while (recv(g.irq[1], &ack, 4, MSG_DONTWAIT) == 4)
				;
		pthread_mutex_lock(&g.sd->lock);
		if (g.sd->stats.stalls != stalls0 && !atomic_load(&g.stall_seen)) {
			atomic_store(&g.replies_at_stall, atomic_load(&g.replies));
			atomic_store(&g.stall_seen, 1);
		}
		pthread_mutex_unlock(&g.sd->lock);
		nanosleep(&ts, 0);
	}
	return 0;
}

/* remoteproc boots the image: "running", or "offline" when the start fails. */
static void kernel_boot(void)
{
	if (g.starts < 16)
		g.start_ns[g.starts] = mono_now_ns();
	g.starts++;
	if (g.start_fails) {
		g.power--;
		snprintf(g.kstate, sizeof(g.kstate), "offline");
		if (g.fails < 16)
			g.fail_ns[g.fails] = mono_now_ns();
		g.fails++;
		return;
	}
	snprintf(g.kstate, sizeof(g.kstate), "running");
	if (g.attach_in_cycle)
		atomic_store(&g.attach_due, 1);
	else
		fw_start();
}

/* servod's cycle thread, amp_linux_cycle() returned, what it said not yet
 * acted on: a started firmware attaches here while the old one's verdict,
 * a stall, is in flight (the window a restart's attach can always land in). */
void __real_telemetry_cycle(struct servod *sd, const struct cycle_wake *w, int rc, const struct amp_rx_info *rx,
			    const struct amp_cmd_axis *cmd, uint32_t n);
void __wrap_telemetry_cycle(struct servod *sd, const struct cycle_wake *w, int rc, const struct amp_rx_info *rx,
			    const struct amp_cmd_axis *cmd, uint32_t n);
void __wrap_telemetry_cycle(struct servod *sd, const struct cycle_wake *w, int rc, const struct amp_rx_info *rx,
			    const struct amp_cmd_axis *cmd, uint32_t n)
{
	__real_telemetry_cycle(sd, w, rc, rx, cmd, n);
	if (rc == AMP_E_STALLED && atomic_exchange(&g.attach_due, 0)) {
		fw_start();
		atomic_fetch_add(&g.attached_in_cycle, 1);
	}
}

/* What remoteproc makes of what servod wrote since the last pass. */
static void rproc_play(void)
{
	char st[32], rep[32], rec[32];

	rfile(g.dir, "state", st, sizeof(st));
	rfile(g.dir, "device/report_crash", rep, sizeof(rep));
	rfile(g.dir, "recovery", rec, sizeof(rec));
	if (rep[0]) {
		wfile(g.dir, "device/report_crash", "");
		g.reports++;
		if (!strcmp(g.kstate, "running")) {
			if (!strcmp(rec, "enabled")) {
				/* rproc_boot_recovery: stop, then start (power held) */
				g.kernel_recoveries++;
				fw_stop();
				snprintf(g.kstate, sizeof(g.kstate), "offline");
				g.power++;	/* kernel_boot's failure takes it back */
				kernel_boot();
			} else {
				snprintf(g.kstate, sizeof(g.kstate), "crashed");
			}
		}
	}
	if (!strcmp(st, "stop")) {
		g.stops++;
		if ((!strcmp(g.kstate, "running") || !strcmp(g.kstate, "crashed")) && --g.power == 0) {
			fw_stop();
			snprintf(g.kstate, sizeof(g.kstate), "offline");
		}
	} else if (!strcmp(st, "start")) {
		if (++g.power == 1)
			kernel_boot();
	}
	wfile(g.dir, "state", g.kstate);
}

#ifdef RECOVERY_CFG_DEFAULT
#define PASS(sd, busy) servod_pass(sd, busy)
#else
/* the servod before this change: main.c's loop */
static void old_pass(struct servod *sd, int *busy)
{
	(void)busy;
	supervise(sd);
	control_serve(sd, 20);
	telemetry_serve(sd);
}
#define PASS(sd, busy) old_pass(sd, busy)
#endif

/* One pass of servod's main loop, then remoteproc. */
static void pass(void)
{
	static int busy;

	PASS(g.sd, &busy);
	rproc_play();
}

static uint64_t stat_of(const uint64_t *field)
{
	uint64_t v;

	pthread_mutex_lock(&g.sd->lock);
	v = *field;
	pthread_mutex_unlock(&g.sd->lock);
	return v;
}

/* Passes until cond holds or about host_s seconds went by (not an assertion:
 * the case's checks follow). */
#define RUN_UNTIL(cond, host_s)                                                     \
	do {                                                                        \
		uint64_t end_ = mono_now_ns() + (uint64_t)((host_s) * 1e9);         \
		while (!(cond) && (int64_t)(mono_now_ns() - end_) < 0)              \
			pass();                                                     \
	} while (0)

static const struct servod_request *request(const char *name)
{
	for (const struct servod_request *r = __start_servod_requests; r < __stop_servod_requests; r++)
		if (!strcmp(r->name, name))
			return r;
	return 0;
}

/* A request as ampctl would send it: the code, msg and the body. */
static int req(const char *line, char *msg, size_t mn, char *body, size_t bn)
{
	char buf[256], *argv[8], *save = 0, *tok;
	struct out o = { malloc(4096), 0, 4096 };
	const struct servod_request *r;
	int argc = 0, rc = -1;

	snprintf(buf, sizeof(buf), "%s", line);
	for (tok = strtok_r(buf, " ", &save); tok && argc < 8; tok = strtok_r(0, " ", &save))
		argv[argc++] = tok;
	msg[0] = 0;
	r = request(argv[0]);
	if (r)
		rc = r->fn(g.sd, &o, argc, argv, msg, mn);
	else
		snprintf(msg, mn, "no request '%s' in servod", argv[0]);
	snprintf(body, bn, "%.*s", (int)o.len, o.buf);
	free(o.buf);
	return rc;
}

static void rig_up(uint32_t limit, uint32_t backoff_ms, int telemetry)
{
	struct servod *sd = aligned_alloc(64, (sizeof(*sd) + 63u) & ~(size_t)63u);
	int fd;

	memset(sd, 0, sizeof(*sd));
	memset(ocm, 0, sizeof(ocm));
	memset(&g, 0, sizeof(g));
	g.sd = sd;
	pthread_mutex_init(&g.fw, 0);
	snprintf(g.dir, sizeof(g.dir), "/tmp/servod-rproc.XXXXXX");
	CHECK(mkdtemp(g.dir) != 0);
	{
		char dev[96];

		snprintf(dev, sizeof(dev), "%s/device", g.dir);
		CHECK_EQ(mkdir(dev, 0755), 0);
	}
	snprintf(g.kstate, sizeof(g.kstate), "offline");
	wfile(g.dir, "state", "offline");
	wfile(g.dir, "recovery", rig_upstream ? "disabled" : "enabled");
	if (!rig_upstream)
		wfile(g.dir, "device/report_crash", "");

	sd->quit = &quit;
	sd->opt.amplitude = 2000.0;
	sd->opt.freq = 0.5;
	sd->opt.prog = (struct prog_opts){ 1000.0, 200.0, 2000.0, 500.0, 1000u, 0, PROG_MAX_S_DEFAULT };
	sd->opt.id = "recovery-test";
	sd->opt.servo_clock_hz = 100000000u;
	sd->opt.telem = "off";
	snprintf(g.pfile, sizeof(g.pfile), "/tmp/servod-rparams.XXXXXX");
	fd = mkstemp(g.pfile);
	CHECK(fd >= 0);
	close(fd);
	unlink(g.pfile);
	sd->opt.param_path = g.pfile;
#ifdef RECOVERY_CFG_DEFAULT
	sd->opt.recovery = (struct recovery_cfg)RECOVERY_CFG_DEFAULT;
	sd->opt.recovery.limit = limit;
	sd->opt.recovery.timeout_ms = 10000;	/* never reached: remoteproc answers at once */
	sd->opt.recovery.backoff_ms = backoff_ms;
	sd->opt.recovery.backoff_max_ms = 8u * backoff_ms;
#else
	(void)limit, (void)backoff_ms;
#endif
	params_load(sd);
	sd->pset[SP_P_wd_limit] = 20;
	sd->axes = sd->pset[SP_P_axes];
	sd->period_ns = sd->pset[SP_P_cycle_period_us] * 1000u;
	sd->ocm = ocm;
	sd->ocm_size = sizeof(ocm);
	sd->listen_fd = -1;
	for (int i = 0; i < CONTROL_CLIENTS; i++)
		sd->clients[i].fd = -1;
	snprintf(sd->rproc.dir, sizeof(sd->rproc.dir), "%s", g.dir);
	pthread_mutex_init(&sd->lock, 0);
	prog_init(&sd->prog, &sd->opt.prog, &sd->lock);
	cycle_stats_new_session(&sd->stats);
	if (telemetry) {
		sd->opt.telem = "127.0.0.1:0";
		CHECK_EQ(telemetry_parse_opt(&sd->opt), 0);
		memcpy(sd->opt.telem_token, TOKEN, sizeof(TOKEN) - 1);
		sd->opt.telem_token_len = sizeof(TOKEN) - 1;
		telemetry_start(sd);
		CHECK(sd->telem_on);
	}
	/* the cycle interrupt: a datagram per cycle, servod's "re-enable" back */
	CHECK_EQ(socketpair(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0, g.irq), 0);
	sd->irq.fd = g.irq[0];
	sd->irq.ttc = ttc_regs;
	sd->irq.ttc_hz = 133000000u;
	atomic_store(&quit, 0);
	CHECK_EQ(pthread_create(&g.cycle_th, 0, cycle_thread, sd), 0);
	CHECK_EQ(pthread_create(&g.tick_th, 0, ticker, 0), 0);
	/* servod initialises the region (remoteproc offline), then the
	 * operator starts the firmware: attached, parameter set loaded */
	RUN_UNTIL(session_open(&sd->session), 10);
	CHECK(session_open(&sd->session));
	wfile(g.dir, "state", "start");
	rproc_play();
	RUN_UNTIL(stat_of(&sd->stats.restores) == 1, 10);
	CHECK_EQ(stat_of(&sd->stats.restores), 1);
	CHECK_EQ(sd->session.state, SESSION_RUNNING);
}

static void rig_down(void)
{
	atomic_store(&g.stop_ticker, 1);
	pthread_join(g.tick_th, 0);
	atomic_store(&quit, 1);
	pthread_join(g.cycle_th, 0);
	telemetry_stop(g.sd);
	close(g.irq[0]);
	close(g.irq[1]);
	{
		char p[160];

		snprintf(p, sizeof(p), "%s/device/report_crash", g.dir);
		unlink(p);
		snprintf(p, sizeof(p), "%s/device", g.dir);
		rmdir(p);
		snprintf(p, sizeof(p), "%s/state", g.dir);
		unlink(p);
		snprintf(p, sizeof(p), "%s/recovery", g.dir);
		unlink(p);
		rmdir(g.dir);
	}
	unlink(g.pfile);
	free(g.sd);
}

static int body_has(const char *body, const char *text)
{
	int ok = strstr(body, text) != 0;

	if (!ok)
		printf("  expected '%s' in:\n%s\n", text, body);
	return ok;
}

/* `ampctl fault` says latched=1 (no mailbox request: the servo may hang) */
static int latched(void)
{
	char msg[256], body[2048];

	return req("fault", msg, sizeof(msg), body, sizeof(body)) == SE_OK && strstr(body, "latched=1");
}

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
	test_bounds();
	test_attach_inside_a_stalled_cycle();
	test_fails_after_every_attach();
	test_failed_restart_retried();
	test_failing_restart_latches();
	test_requests_do_not_starve();
	test_operator_stop_is_final();
	test_operator_stop_during_recovery();
	test_stop_and_start_between_passes();
	test_driver_without_report_crash();
	return check_summary("servod recovery");
}
