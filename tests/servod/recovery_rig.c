// SPDX-License-Identifier: MIT
/*
 * recovery_rig.c - the rig of servod's recovery tests (recovery_rig.h):
 * servod's supervisor, cycle thread, parameter service and telemetry server
 * against a servo on a host buffer and remoteproc played in a directory
 * (test_servod_recovery.c says what each plays).
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

extern const struct servod_request __start_servod_requests[];
extern const struct servod_request __stop_servod_requests[];

const char TOKEN[] = "0123456789abcdef0123456789abcdef";

static _Alignas(64) uint8_t ocm[AMP_OCM_SIZE];
static _Alignas(64) uint8_t ttc_regs[4096];
static atomic_int quit;

/* ---- the rig ------------------------------------------------------------------ */

struct rig g;
/* the next rig_up plays a driver without device/report_crash whose own
 * recovery is disabled at probe (the upstream xlnx_r5_remoteproc) */
int rig_upstream;

void wfile(const char *dir, const char *name, const char *text)
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

void rfile(const char *dir, const char *name, char *buf, size_t n)
{
	char p[160];

	snprintf(p, sizeof(p), "%s/%s", dir, name);
	if (sysfs_read(p, buf, n))
		buf[0] = 0;
}

/* The firmware attaches (a start; refused: again every cycle) / stops
 * (parked: its line left as it is). */
void fw_start(void)
{
	pthread_mutex_lock(&g.fw);
	g.attach_retry = amp_servo_attach(&g.s, ocm, sizeof(ocm)) != AMP_OK;
	g.running = 1;
	g.hang = 0;
	g.cycles = 0;
	g.sets = 0;
	pthread_mutex_unlock(&g.fw);
}

void fw_stop(void)
{
	pthread_mutex_lock(&g.fw);
	g.running = 0;
	pthread_mutex_unlock(&g.fw);
}

void fw_hang(void)
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
		if (g.running && g.attach_retry)
			g.attach_retry = amp_servo_attach(&g.s, ocm, sizeof(ocm)) != AMP_OK;
		if (g.running && !g.hang && !g.attach_retry) {
			int rc = amp_servo_cycle_rx(&g.s, 0, &rx);

			if (rc == AMP_E_STALLED)
				g.wd_stalls++;
			if (rc == AMP_E_PEER_ABSENT) {
				/* closed or re-initialised: attach again (as
				 * rpu_app's link does, after its safe stop) */
				g.attach_retry = 1;
				g.absent++;
			} else {
				(void)amp_servo_cycle_tx(&g.s, fb, 4, 0, 0);
				fw_serve();
				g.cycles++;
				if (g.hang_after_attach && g.sets && g.cycles > 30)
					g.hang = 1;
			}
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
void rproc_play(void)
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
void pass(void)
{
	static int busy;

	PASS(g.sd, &busy);
	rproc_play();
}

uint64_t stat_of(const uint64_t *field)
{
	uint64_t v;

	pthread_mutex_lock(&g.sd->lock);
	v = *field;
	pthread_mutex_unlock(&g.sd->lock);
	return v;
}


static const struct servod_request *request(const char *name)
{
	for (const struct servod_request *r = __start_servod_requests; r < __stop_servod_requests; r++)
		if (!strcmp(r->name, name))
			return r;
	return 0;
}

/* A request as ampctl would send it: the code, msg and the body. */
int req(const char *line, char *msg, size_t mn, char *body, size_t bn)
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

void rig_up(uint32_t limit, uint32_t backoff_ms, int telemetry)
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

void rig_down(void)
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

int body_has(const char *body, const char *text)
{
	int ok = strstr(body, text) != 0;

	if (!ok)
		printf("  expected '%s' in:\n%s\n", text, body);
	return ok;
}

/* `ampctl fault` says latched=1 (no mailbox request: the servo may hang) */
int latched(void)
{
	char msg[256], body[2048];

	return req("fault", msg, sizeof(msg), body, sizeof(body)) == SE_OK && strstr(body, "latched=1");
}

/* The rig's own checks (check.h counts per file), for the case's summary. */
void rig_checks(unsigned *passed, unsigned *failed)
{
	*passed = check_pass;
	*failed = check_fail;
}
