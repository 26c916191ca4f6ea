// SPDX-License-Identifier: MIT
/*
 * servod - the Linux side of the servo cycle (seed 000's Linux steps).
 *
 *   servod [-s SOCKET] [-p PARAMFILE] [-a AMPLITUDE_INC] [-f FREQ_HZ]
 *          [--ttc-hz HZ] [--servo-clock-hz HZ] [--prio N]
 *          [--telemetry ADDR:PORT|off] [--id CONTROLLER_ID]
 *          [--inc-per-mm N] [--vmax MM_S] [--amax MM_S2] [--travel MM]
 *          [--idle sine|hold] [-v]
 *
 * Cycle thread (SCHED_FIFO, mlockall): waits for the cycle interrupt with
 * read() on the UIO device "cycle-interrupt", acknowledges its own flag
 * (TTC1 counter 1's clear-on-read interrupt register, mapped through the
 * same UIO device) and re-enables the interrupt (write 1), then runs
 * amp_linux_cycle(): heartbeat, semaphore, feedback read, coarse setpoints
 * written (a sine per axis, or a G-code program's setpoints popped from a
 * lock-free ring: program.c), semaphore set. It counts cycles, exchanges,
 * missed interrupts (time between two wake-ups), late cycles and its
 * wake-up latency (interrupt to thread running, read from the counter of
 * its own TTC counter, which restarts at every interval event).
 *
 * Main thread: the supervisor and the local service.
 *  - amp_linux_init() only while remoteproc says the servo is offline (new
 *    epoch); when the servo runs but is not attached to this servod's
 *    region, it waits until it goes offline.
 *  - after every attach (attach_count changed: first start, restart,
 *    recovery) it loads the authoritative parameter set (file, written
 *    atomically) into the servo with one SP_CMD_PARAM_SET_MANY.
 *  - amp_linux_cycle() == AMP_E_STALLED (servo heartbeat still for
 *    wd_limit cycles): reports a crash to remoteproc through the driver's
 *    report_crash attribute; remoteproc's recovery stops and restarts the
 *    firmware, which re-attaches in the same epoch.
 *  - a Unix socket serves status, statistics and the parameter service
 *    to ampctl.
 *
 * Telemetry (linux/telemetry, docs/telemetry.md, default 0.0.0.0:7700): the
 * cycle thread pushes one record per cycle right after amp_linux_cycle()
 * into the library's lock-free ring (no syscall, no lock, never waits; a
 * full ring drops and counts). The main thread pushes parameter changes
 * (every `param set`, and the whole set loaded at each attach), a GAP event
 * at each attach (controller_restart, or recovery after a stall servod
 * reported) and servod's own log lines; the trace thread (normal priority)
 * forwards the firmware's remoteproc trace lines as LOG "rpu_app".
 */
#define _GNU_SOURCE
#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <poll.h>
#include <pthread.h>
#include <sched.h>
#include <signal.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <time.h>
#include <unistd.h>

#include "amp/amp.h"
#include "servoamp/servo_proto.h"
#include "program.h"
#include "servod.h"
#include "telem.h"

#define TTC_CLK_CTRL1 0x04u	/* counter 1 clock control (prescaler) */
#define TTC_CNT_VAL1  0x1cu	/* counter 1 value */
#define TTC_ISR1      0x58u	/* counter 1 interrupt register, clear on read */
#define MBOX_TIMEOUT_MS 200
#define HIST_N 10

static const struct sp_param_desc params[] = SP_PARAM_TABLE_INIT;
static const uint32_t hist_edges_us[HIST_N - 1] = { 10, 20, 50, 100, 200, 300, 500, 1000, 2000 };

static struct {
	const char *sock_path;
	const char *param_path;
	double amplitude;	/* inc */
	double freq;		/* Hz */
	uint32_t ttc_hz;
	int prio;
	int verbose;
	uint32_t servo_clock_hz;	/* rate of the feedback's t_cycle / irq_latency ticks */
	const char *telem;		/* ADDR:PORT or "off" */
	const char *id;			/* controller id in the telemetry HELLO */
	struct prog_opts prog;		/* G-code runner: scale, planner limits, idle mode */
} opt = { SERVOD_SOCKET, SERVOD_PARAMS, 2000.0, 0.5, 133000000u, 80, 0, 100000000u, "0.0.0.0:7700",
	  "zynq7000_qemu", { 1000.0, 200.0, 2000.0, 500.0, 1000u, 0 } };

/* Telemetry (static: the struct is 64-byte aligned). */
static struct telem telem;
static int telem_on;
static char telem_addr[64];
static uint16_t telem_port_opt = TELEM_DEFAULT_PORT;
static _Thread_local int in_cycle_thread;	/* logm() never pushes from the cycle thread */

/* Counters published for readers that must not take amp_lock (the
 * telemetry drain thread's STATS): relaxed 64-bit atomics, lock-free on
 * ARMv7-A (LDREXD/STREXD) as on x86-64. */
static struct {
	_Atomic uint64_t wakes, cycles, exchanges, absent, missed_irq, late, stalls;
	_Atomic uint64_t stall_cycle;	/* servod cycle at which the last stall was detected */
	_Atomic uint64_t recoveries, restores;
} pub;

/* The authoritative parameter set (words, as on the wire). */
static uint32_t pset[SP_P_COUNT];

static struct amp_linux amp;
static pthread_mutex_t amp_lock;
static volatile uint8_t *ocm, *ttc;
static uint32_t ocm_size;
static int uio_cycle_fd = -1;
static char rproc_dir[300];

/* Session (protected by amp_lock). */
static int session;		/* amp_linux_init done for the current servo run */
static int seen_running;	/* remoteproc said "running" during this session */
static uint32_t epoch;

/* Statistics of the cycle thread (written under amp_lock). */
static struct {
	uint64_t wakes;		/* cycle interrupts taken */
	uint64_t cycles;	/* amp_linux_cycle calls (session open) */
	uint64_t exchanges;	/* cycles with the servo attached and a fresh feedback */
	uint64_t absent;	/* cycles with the servo not attached */
	uint64_t missed_irq;	/* cycle interrupts never seen (time gaps) */
	uint64_t uio_skips;	/* UIO event count jumped by more than 1 */
	uint64_t late;		/* commands published after T/2 (the servo reads them then) */
	uint64_t stalls;	/* AMP_E_STALLED episodes reported */
	uint32_t lat_min, lat_max;	/* wake-up latency, ns */
	uint64_t lat_sum, lat_n;
	uint64_t hist[HIST_N];
	uint32_t work_max;	/* ns: wake-up to commands published */
	uint64_t work_sum;
	/* window markers: Linux cycle vs the servo's cycle in the last feedback */
	uint32_t servo_cycle;
	uint32_t servo_cmd_seq;
	/* last stall: Linux cycles and ms from the servo's last heartbeat change to detection */
	uint32_t stall_cycles;
	uint32_t stall_us;
} st;
static uint32_t last_servo_hb;
static uint64_t last_servo_hb_t, last_servo_hb_cycle;

static atomic_int stall_pending;
static uint32_t stall_attach = UINT32_MAX;	/* attach_count already reported (cycle thread) */
static uint32_t restored_attach;		/* attach_count whose parameters were loaded */
static uint64_t restores, recoveries, restore_errors;
static int recovering;
static struct timespec recover_t0;
static volatile sig_atomic_t quit;
static uint32_t period_ns = 1000000u;
static uint32_t motion_axes = 4;

static void vlogl(uint32_t level, const char *fmt, va_list ap)
{
	struct timespec ts;
	char line[TELEM_LOG_MAX];
	int n;

	clock_gettime(CLOCK_MONOTONIC, &ts);
	n = vsnprintf(line, sizeof(line), fmt, ap);
	fprintf(stderr, "servod[%ld.%03ld]: %s\n", (long)ts.tv_sec, ts.tv_nsec / 1000000, line);
	/* never from the cycle thread: the event queue takes a mutex */
	if (telem_on && !in_cycle_thread && n > 0)
		telem_push_log(&telem, 0, level, "servod", line,
			       (size_t)n < sizeof(line) ? (size_t)n : sizeof(line) - 1);
}

static void logm(const char *fmt, ...)
{
	va_list ap;

	va_start(ap, fmt);
	vlogl(TELEM_LOG_INFO, fmt, ap);
	va_end(ap);
}

static void logw(const char *fmt, ...)
{
	va_list ap;

	va_start(ap, fmt);
	vlogl(TELEM_LOG_WARNING, fmt, ap);
	va_end(ap);
}

static uint64_t now_ns(void)
{
	struct timespec ts;

	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (uint64_t)ts.tv_sec * 1000000000u + (uint64_t)ts.tv_nsec;
}

/* ---- parameters: text forms and the file ------------------------------- */

static int param_by_name(const char *s)
{
	char *end;
	unsigned long id;

	for (int i = 0; i < SP_P_COUNT; i++)
		if (!strcmp(params[i].name, s))
			return i;
	id = strtoul(s, &end, 0);
	if (*s && !*end && id < SP_P_COUNT)
		return (int)id;
	return -1;
}

static float f_of(uint32_t w)
{
	float f;

	memcpy(&f, &w, 4);
	return f;
}

static uint32_t w_of(float f)
{
	uint32_t w;

	memcpy(&w, &f, 4);
	return w;
}

static void fmt_value(const struct sp_param_desc *d, uint32_t w, char *buf, size_t n)
{
	switch (d->type) {
	case SP_T_F32: snprintf(buf, n, "%.9g", (double)f_of(w)); break;
	case SP_T_I32: snprintf(buf, n, "%d", (int32_t)w); break;
	default: snprintf(buf, n, "%u", w); break;
	}
}

static void fmt_num(const struct sp_param_desc *d, double v, char *buf, size_t n)
{
	if (d->type == SP_T_F32)
		snprintf(buf, n, "%.9g", (double)(float)v);
	else
		snprintf(buf, n, "%.0f", v);
}

/* Parse and range-check a value: SE_OK and *w, or SE_VALUE with a message. */
static int parse_value(const struct sp_param_desc *d, const char *s, uint32_t *w, char *msg, size_t n)
{
	char *end, lo[32], hi[32];
	int ok = 1;

	fmt_num(d, d->min, lo, sizeof(lo));
	fmt_num(d, d->max, hi, sizeof(hi));
	errno = 0;
	if (d->type == SP_T_F32) {
		float f = strtof(s, &end);

		if (!*s || *end || errno || isnan(f))
			ok = -1;
		else if (f < (float)d->min || f > (float)d->max)
			ok = 0;
		*w = w_of(f);
	} else if (d->type == SP_T_I32) {
		long long v = strtoll(s, &end, 0);

		if (!*s || *end || errno)
			ok = -1;
		else if (v < (long long)d->min || v > (long long)d->max)
			ok = 0;
		*w = (uint32_t)(int32_t)v;
	} else {
		long long v = strtoll(s, &end, 0);

		if (!*s || *end || errno)
			ok = -1;
		else if (v < (long long)d->min || v > (long long)d->max)
			ok = 0;
		*w = (uint32_t)v;
	}
	if (ok < 0) {
		snprintf(msg, n, "%s: '%s' is not a%s %s", d->name, s,
			 d->type == SP_T_F32 ? "" : "n", d->type == SP_T_F32 ? "number" : "integer");
		return SE_VALUE;
	}
	if (!ok) {
		snprintf(msg, n, "%s: %s out of range [%s, %s]%s%s", d->name, s, lo, hi,
			 *d->unit ? " " : "", d->unit);
		return SE_VALUE;
	}
	if ((d->flags & SP_F_RO) && *w != pset[d->id]) {
		snprintf(msg, n, "%s is read-only", d->name);
		return SE_VALUE;
	}
	return SE_OK;
}

static void params_defaults(void)
{
	for (int i = 0; i < SP_P_COUNT; i++) {
		const struct sp_param_desc *d = &params[i];

		pset[i] = d->type == SP_T_F32 ? w_of((float)d->def) :
			  d->type == SP_T_I32 ? (uint32_t)(int32_t)d->def : (uint32_t)d->def;
	}
}

static void params_load(void)
{
	FILE *f = fopen(opt.param_path, "r");
	char line[256], name[64], val[64], msg[160];
	int n = 0;

	params_defaults();
	if (!f) {
		logm("no parameter file %s: defaults", opt.param_path);
		return;
	}
	while (fgets(line, sizeof(line), f)) {
		int id;
		uint32_t w;

		if (line[0] == '#' || sscanf(line, "%63s %63s", name, val) != 2)
			continue;
		id = param_by_name(name);
		if (id < 0) {
			logm("%s: unknown parameter '%s' ignored", opt.param_path, name);
			continue;
		}
		if (parse_value(&params[id], val, &w, msg, sizeof(msg)) != SE_OK) {
			logm("%s: %s (default kept)", opt.param_path, msg);
			continue;
		}
		pset[id] = w;
		n++;
	}
	fclose(f);
	logm("loaded %d parameter(s) from %s", n, opt.param_path);
}

/* write temp + fsync + rename + fsync(dir) */
static int params_save(void)
{
	char tmp[300], dir[300], v[48];
	FILE *f;
	int fd;
	char *slash;

	snprintf(dir, sizeof(dir), "%s", opt.param_path);
	slash = strrchr(dir, '/');
	if (slash && slash != dir) {
		*slash = 0;
		mkdir(dir, 0755);
	} else {
		snprintf(dir, sizeof(dir), ".");
	}
	snprintf(tmp, sizeof(tmp), "%s.tmp", opt.param_path);
	f = fopen(tmp, "w");
	if (!f)
		return -1;
	fprintf(f, "# servod parameter set (servoamp/servo_proto.h); loaded into the servo at every attach\n");
	for (int i = 0; i < SP_P_COUNT; i++) {
		if (!(params[i].flags & SP_F_RESTORE))
			continue;
		fmt_value(&params[i], pset[i], v, sizeof(v));
		fprintf(f, "%s %s\n", params[i].name, v);
	}
	if (fflush(f) || fsync(fileno(f))) {
		fclose(f);
		return -1;
	}
	fclose(f);
	if (rename(tmp, opt.param_path))
		return -1;
	fd = open(dir, O_RDONLY | O_DIRECTORY);
	if (fd >= 0) {
		fsync(fd);
		close(fd);
	}
	return 0;
}

/* ---- devices ----------------------------------------------------------- */

static int read_file(const char *path, char *buf, size_t n)
{
	int fd = open(path, O_RDONLY);
	ssize_t r;

	if (fd < 0)
		return -1;
	r = read(fd, buf, n - 1);
	close(fd);
	if (r < 0)
		return -1;
	buf[r] = 0;
	while (r > 0 && (buf[r - 1] == '\n' || buf[r - 1] == ' '))
		buf[--r] = 0;
	return 0;
}

static int write_file(const char *path, const char *s)
{
	int fd = open(path, O_WRONLY);
	ssize_t r;

	if (fd < 0)
		return -1;
	r = write(fd, s, strlen(s));
	close(fd);
	return r < 0 ? -1 : 0;
}

/* /dev/uioN whose name starts with prefix; maps map0. */
static int uio_open(const char *prefix, volatile uint8_t **base, uint32_t *size, uint32_t *offs)
{
	DIR *d = opendir("/sys/class/uio");
	struct dirent *e;
	char path[600], buf[64];
	int fd = -1;

	if (!d)
		return -1;
	while ((e = readdir(d))) {
		if (strncmp(e->d_name, "uio", 3))
			continue;
		snprintf(path, sizeof(path), "/sys/class/uio/%s/name", e->d_name);
		if (read_file(path, buf, sizeof(buf)) || strncmp(buf, prefix, strlen(prefix)))
			continue;
		snprintf(path, sizeof(path), "/sys/class/uio/%s/maps/map0/size", e->d_name);
		if (read_file(path, buf, sizeof(buf)))
			break;
		*size = (uint32_t)strtoul(buf, 0, 0);
		snprintf(path, sizeof(path), "/sys/class/uio/%s/maps/map0/offset", e->d_name);
		*offs = read_file(path, buf, sizeof(buf)) ? 0 : (uint32_t)strtoul(buf, 0, 0);
		snprintf(path, sizeof(path), "/dev/%s", e->d_name);
		fd = open(path, O_RDWR | O_CLOEXEC);
		if (fd < 0)
			break;
		void *p = mmap(0, *size, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
		if (p == MAP_FAILED) {
			close(fd);
			fd = -1;
			break;
		}
		*base = p;
		logm("%s: %s, map0 %u bytes (offset 0x%x)", prefix, path, *size, *offs);
		break;
	}
	closedir(d);
	return fd;
}

static int find_rproc(void)
{
	DIR *d = opendir("/sys/class/remoteproc");
	struct dirent *e;
	char path[600], buf[64];

	if (!d)
		return -1;
	while ((e = readdir(d))) {
		if (strncmp(e->d_name, "remoteproc", 10))
			continue;
		snprintf(path, sizeof(path), "/sys/class/remoteproc/%s/name", e->d_name);
		if (!read_file(path, buf, sizeof(buf)) && !strcmp(buf, "servo-cpu1")) {
			snprintf(rproc_dir, sizeof(rproc_dir), "/sys/class/remoteproc/%s", e->d_name);
			closedir(d);
			return 0;
		}
	}
	closedir(d);
	return -1;
}

static const char *rproc_state(void)
{
	static char buf[32];
	char path[600];

	if (!rproc_dir[0] && find_rproc())
		return "absent";
	snprintf(path, sizeof(path), "%s/state", rproc_dir);
	if (read_file(path, buf, sizeof(buf))) {
		rproc_dir[0] = 0;	/* driver unloaded? look again next time */
		return "absent";
	}
	return buf;
}

static uint32_t ocm_rd(const volatile uint32_t *p)
{
	return __atomic_load_n(p, __ATOMIC_ACQUIRE);
}

/* ---- cycle thread ------------------------------------------------------ */

static uint32_t ttc_ns_per_tick_q16(void)
{
	uint32_t clk = *(volatile uint32_t *)(ttc + TTC_CLK_CTRL1);
	uint64_t div = (clk & 1u) ? 2ull << ((clk >> 1) & 0xfu) : 1u;

	return (uint32_t)((div * 1000000000ull * 65536u) / opt.ttc_hz);
}

static void *cycle_thread(void *arg)
{
	struct amp_cmd_axis cmd[AMP_MAX_AXES];
	uint32_t last_count = 0, one = 1;
	uint64_t last_wake = 0;
	int have_count = 0;

	(void)arg;
	in_cycle_thread = 1;
	memset(cmd, 0, sizeof(cmd));
	while (!quit) {
		struct pollfd pfd = { uio_cycle_fd, POLLIN, 0 };
		uint32_t count, ticks, lat, q16;
		uint64_t t_wake, t_done;
		struct amp_rx_info rx;
		int rc;

		if (poll(&pfd, 1, 100) <= 0) {
			/* No interrupt for 100 ms (servo stopped, or a previous
			 * servod died between an interrupt and its re-enable):
			 * acknowledge and re-arm; idempotent in uio_pdrv_genirq. */
			(void)*(volatile uint32_t *)(ttc + TTC_ISR1);
			if (write(uio_cycle_fd, &one, 4) != 4)
				logm("uio: re-enable failed: %s", strerror(errno));
			continue;
		}
		if (read(uio_cycle_fd, &count, 4) != 4)
			continue;
		t_wake = now_ns();
		/* 1. clear the interrupt flag (ours only) and re-enable it */
		ticks = *(volatile uint32_t *)(ttc + TTC_CNT_VAL1) & 0xffffu;
		(void)*(volatile uint32_t *)(ttc + TTC_ISR1);
		if (write(uio_cycle_fd, &one, 4) != 4)
			logm("uio: re-enable failed: %s", strerror(errno));
		q16 = ttc_ns_per_tick_q16();
		lat = (uint32_t)(((uint64_t)ticks * q16) >> 16);

		pthread_mutex_lock(&amp_lock);
		st.wakes++;
		if (have_count && count - last_count > 1u)
			st.uio_skips += count - last_count - 1u;
		last_count = count;
		have_count = 1;
		/* missed interval events: between the events' own times (wake-up
		 * minus the latency read from the counter), not between wake-ups */
		if (last_wake) {
			uint64_t dt = (t_wake - lat) - last_wake;
			uint64_t n = (dt + period_ns / 2u) / period_ns;

			if (n > 1u)
				st.missed_irq += n - 1u;
		}
		last_wake = t_wake - lat;
		if (lat < st.lat_min || !st.lat_n)
			st.lat_min = lat;
		if (lat > st.lat_max)
			st.lat_max = lat;
		st.lat_sum += lat;
		st.lat_n++;
		{
			int b = 0;

			while (b < HIST_N - 1 && lat >= hist_edges_us[b] * 1000u)
				b++;
			st.hist[b]++;
		}
		if (session) {
			uint32_t n = motion_axes;
			double t = (double)amp.cycle * (double)period_ns * 1e-9;

			for (uint32_t i = 0; i < n; i++) {
				cmd[i].control_word = AMP_AXIS_ENABLE;
				cmd[i].target_pos = (int32_t)lround(opt.amplitude *
					sin(2.0 * M_PI * opt.freq * t + (double)i * M_PI / 4.0));
				cmd[i].vel_ff = 0;
				cmd[i].torque_offset = 0;
			}
			/* a G-code program (or the hold after one) replaces the sine:
			 * one setpoint popped from a lock-free ring (program.c) */
			prog_cycle(cmd, n, amp.cmd_seq + 1u);
			/* 2-5: semaphore, feedback, commands, semaphore */
			memset(&rx, 0, sizeof(rx));
			rc = amp_linux_cycle(&amp, cmd, n, SP_CMDF_MOTION, &rx);
			t_done = now_ns();
			prog_feedback(rc, &amp.fb, n,
				      (rc == AMP_OK || rc == AMP_E_PEER_ERROR) &&
				      (rx.status == AMP_RX_FRESH || rx.status == AMP_RX_MISSED));
			st.cycles++;
			if (telem_on) {
				/* one record per cycle into the lock-free ring: no
				 * syscall, no lock, never waits (full: dropped and
				 * counted by the library, announced as a GAP) */
				struct telem_cycle tr;

				tr.cycle = st.cycles;
				tr.t_ns = t_wake;
				tr.servo_cycle = amp.fb.cycle;
				tr.t_cycle = amp.fb.t_cycle;
				tr.irq_latency = amp.fb.irq_latency;
				tr.wake_latency_ns = lat;
				/* AMP_RX_* and TELEM_X_* have the same values */
				tr.exchange = (rc == AMP_OK || rc == AMP_E_PEER_ERROR) ? rx.status : TELEM_X_NONE;
				tr.missed = rx.missed;
				tr.servo_status = amp.fb.status;
				tr.result = rc;
				tr.n_axes = n;
				memcpy(tr.cmd, cmd, n * sizeof(cmd[0]));
				memcpy(tr.fb, amp.fb.axis, n * sizeof(tr.fb[0]));
				telem_push_cycle(&telem, &tr);
			}
			{
				uint32_t hb = ocm_rd(&amp.ocm->servo_line.heartbeat);

				if (hb != last_servo_hb || !last_servo_hb_t) {
					last_servo_hb = hb;
					last_servo_hb_t = t_wake;
					last_servo_hb_cycle = st.cycles;
				}
			}
			{
				uint32_t work = (uint32_t)(t_done - t_wake);

				if (work > st.work_max)
					st.work_max = work;
				st.work_sum += work;
				if ((uint64_t)lat + work > period_ns / 2u)
					st.late++;
			}
			if (rc == AMP_E_PEER_ABSENT) {
				st.absent++;
			} else if (rc == AMP_E_STALLED) {
				uint32_t ac = ocm_rd(&amp.ocm->servo_line.attach_count);

				if (stall_attach != ac) {
					stall_attach = ac;
					st.stalls++;
					st.stall_cycles = (uint32_t)(st.cycles - last_servo_hb_cycle);
					st.stall_us = (uint32_t)((t_wake - last_servo_hb_t) / 1000u);
					atomic_store_explicit(&pub.stall_cycle, st.cycles, memory_order_relaxed);
					atomic_store(&stall_pending, 1);
				}
			} else if (rc == AMP_OK || rc == AMP_E_PEER_ERROR) {
				if (rx.status == AMP_RX_FRESH || rx.status == AMP_RX_MISSED)
					st.exchanges++;
				st.servo_cycle = amp.fb.cycle;
				st.servo_cmd_seq = amp.fb.cmd_seq;
			}
		}
		atomic_store_explicit(&pub.wakes, st.wakes, memory_order_relaxed);
		atomic_store_explicit(&pub.cycles, st.cycles, memory_order_relaxed);
		atomic_store_explicit(&pub.exchanges, st.exchanges, memory_order_relaxed);
		atomic_store_explicit(&pub.absent, st.absent, memory_order_relaxed);
		atomic_store_explicit(&pub.missed_irq, st.missed_irq, memory_order_relaxed);
		atomic_store_explicit(&pub.late, st.late, memory_order_relaxed);
		atomic_store_explicit(&pub.stalls, st.stalls, memory_order_relaxed);
		pthread_mutex_unlock(&amp_lock);
	}
	return 0;
}

/* ---- mailbox ------------------------------------------------------------ */

/* SE_OK and the servo's status in *status, or SE_OFFLINE / SE_TIMEOUT / SE_SERVO. */
static int mbox(uint32_t command, const void *req, uint32_t len, void *resp, uint32_t cap,
		uint32_t *rlen, int32_t *status, char *msg, size_t n)
{
	struct amp_msg q = { command, 0, len, len, (void *)req };
	struct amp_msg r = { 0, 0, 0, cap, resp };
	uint64_t t0 = now_ns();
	int rc;

	for (;;) {
		pthread_mutex_lock(&amp_lock);
		rc = session ? amp_linux_mbox_post(&amp, &q) : AMP_E_PEER_ABSENT;
		pthread_mutex_unlock(&amp_lock);
		if (rc != AMP_E_BUSY || now_ns() - t0 > MBOX_TIMEOUT_MS * 1000000ull)
			break;
		usleep(200);
	}
	if (rc == AMP_OK) {
		for (;;) {
			usleep(200);
			pthread_mutex_lock(&amp_lock);
			rc = amp_linux_mbox_poll(&amp, &r);
			if (rc == AMP_E_BUSY && now_ns() - t0 > MBOX_TIMEOUT_MS * 1000000ull) {
				amp.mbox_pending = 0;	/* as amp_linux_mbox_call does */
				amp.st.mbox_err++;
				rc = AMP_E_TIMEOUT;
			}
			pthread_mutex_unlock(&amp_lock);
			if (rc != AMP_E_BUSY)
				break;
		}
	}
	switch (rc) {
	case AMP_OK:
		*status = r.status;
		if (rlen)
			*rlen = r.length;
		return SE_OK;
	case AMP_E_PEER_ABSENT:
		snprintf(msg, n, "servo not running (remoteproc %s, not attached to servod's region)",
			 rproc_state());
		return SE_OFFLINE;
	case AMP_E_TIMEOUT:
	case AMP_E_BUSY:
		snprintf(msg, n, "servo did not answer within %d ms (%s)", MBOX_TIMEOUT_MS, amp_strerror(rc));
		return SE_TIMEOUT;
	default:
		snprintf(msg, n, "mailbox: %s (%d)", amp_strerror(rc), rc);
		return rc == AMP_E_NOSPC ? SE_VALUE : SE_SERVO;
	}
}

static const char *sp_strerror(int32_t s)
{
	switch (s) {
	case SP_OK: return "ok";
	case SP_E_CMD: return "unknown command (SP_E_CMD)";
	case SP_E_LENGTH: return "bad payload length (SP_E_LENGTH)";
	case SP_E_ID: return "unknown parameter id (SP_E_ID)";
	case SP_E_RANGE: return "value out of range (SP_E_RANGE)";
	case SP_E_READONLY: return "read-only parameter (SP_E_READONLY)";
	case SP_E_STATE: return "not possible in this state (SP_E_STATE)";
	default: return amp_strerror(s);
	}
}

static int servo_status(struct sp_status *s, char *msg, size_t n)
{
	uint32_t len = 0;
	int32_t status;
	int rc = mbox(SP_CMD_STATUS, 0, 0, s, sizeof(*s), &len, &status, msg, n);

	if (rc)
		return rc;
	if (status || len != sizeof(*s)) {
		snprintf(msg, n, "status: %s", sp_strerror(status));
		return SE_SERVO;
	}
	return SE_OK;
}

/* Load the whole parameter set into the servo (one SET_MANY). */
static int restore_params(char *msg, size_t n)
{
	uint32_t req[1 + 2 * SP_P_COUNT], resp[4], cnt = 0, len;
	int32_t status;
	int rc;

	for (int i = 0; i < SP_P_COUNT; i++) {
		if (!(params[i].flags & SP_F_RESTORE))
			continue;
		req[1 + 2 * cnt] = (uint32_t)i;
		req[2 + 2 * cnt] = pset[i];
		cnt++;
	}
	req[0] = cnt;
	rc = mbox(SP_CMD_PARAM_SET_MANY, req, 4u * (1u + 2u * cnt), resp, sizeof(resp), &len, &status, msg, n);
	if (rc == SE_OK && status) {
		snprintf(msg, n, "servo refused the parameter set: %s", sp_strerror(status));
		rc = SE_SERVO;
	}
	return rc;
}

static void apply_local(uint32_t id, uint32_t w)
{
	pthread_mutex_lock(&amp_lock);
	if (id == SP_P_cycle_period_us)
		period_ns = w * 1000u;
	else if (id == SP_P_wd_limit)
		amp.wd.limit = w;
	else if (id == SP_P_axes)
		motion_axes = w;
	pthread_mutex_unlock(&amp_lock);
}

/* ---- telemetry (never called from the cycle thread) ---------------------- */

static double param_double(const struct sp_param_desc *d, uint32_t w)
{
	switch (d->type) {
	case SP_T_F32: return (double)f_of(w);
	case SP_T_I32: return (double)(int32_t)w;
	default: return (double)w;
	}
}

/* A parameter change on /servoamp/param (servo_proto's types are telem's). */
static void telem_param(uint32_t id, uint32_t w)
{
	const struct sp_param_desc *d = &params[id];

	if (telem_on)
		telem_push_param(&telem, 0, id, d->name, d->type, param_double(d, w), d->unit);
}

/* STATS application counters, on the drain thread: published copies only. */
static unsigned telem_counters(void *arg, struct telem_counter *out, unsigned max)
{
	static const struct {
		const char *name;
		_Atomic uint64_t *v;
	} c[] = {
		{ "servod.wakes", &pub.wakes },		{ "servod.cycles", &pub.cycles },
		{ "servod.exchanges", &pub.exchanges },	{ "servod.absent", &pub.absent },
		{ "servod.missed_irq", &pub.missed_irq }, { "servod.late", &pub.late },
		{ "servod.stalls", &pub.stalls },	{ "servod.recoveries", &pub.recoveries },
		{ "servod.restores", &pub.restores },
	};
	unsigned n = 0;

	(void)arg;
	for (; n < max && n < sizeof(c) / sizeof(c[0]); n++) {
		snprintf(out[n].name, sizeof(out[n].name), "%s", c[n].name);
		out[n].value = atomic_load_explicit(c[n].v, memory_order_relaxed);
	}
	return n;
}

static uint32_t trace_level(const char *s, size_t n)
{
	if ((n >= 8 && !strncmp(s, "warning:", 8)) || memmem(s, n, "WARN", 4))
		return TELEM_LOG_WARNING;
	if (memmem(s, n, "FAULT", 5) || memmem(s, n, "fault:", 6) || memmem(s, n, "error", 5) ||
	    memmem(s, n, "CRASH", 5) || memmem(s, n, "crash", 5))
		return TELEM_LOG_ERROR;
	return TELEM_LOG_INFO;
}

/* The firmware's trace buffer (remoteproc debugfs trace0) -> LOG "rpu_app".
 * The buffer is circular and debugfs shows it up to its NUL (the firmware's
 * write position): new text is what lies beyond the part already sent.
 * When the part already sent is no longer there as it was (shorter, or
 * other bytes), the firmware wrapped or restarted (its log_init clears the
 * buffer): read it from the start again. Only whole lines are sent. Normal
 * priority, every 200 ms. */
static void *trace_thread(void *arg)
{
	static char buf[64 * 1024], prev[64 * 1024];
	char path[600] = "";
	size_t off = 0;

	(void)arg;
	while (!quit) {
		struct timespec ts = { 0, 200 * 1000000L };
		int fd;
		ssize_t len = 0, r;

		nanosleep(&ts, 0);
		if (!path[0]) {
			DIR *d = opendir("/sys/class/remoteproc");
			struct dirent *e;
			char npath[600], name[64];

			while (d && (e = readdir(d))) {
				if (strncmp(e->d_name, "remoteproc", 10))
					continue;
				snprintf(npath, sizeof(npath), "/sys/class/remoteproc/%s/name", e->d_name);
				if (!read_file(npath, name, sizeof(name)) && !strcmp(name, "servo-cpu1")) {
					snprintf(path, sizeof(path), "/sys/kernel/debug/remoteproc/%s/trace0",
						 e->d_name);
					break;
				}
			}
			if (d)
				closedir(d);
			if (!path[0])
				continue;
		}
		fd = open(path, O_RDONLY | O_CLOEXEC);
		if (fd < 0) {
			off = 0;	/* firmware stopped: its next run starts a new trace */
			continue;
		}
		while (len < (ssize_t)sizeof(buf) - 1 &&
		       (r = read(fd, buf + len, sizeof(buf) - 1 - (size_t)len)) > 0)
			len += r;
		close(fd);
		if (len > 0 && buf[len - 1] == 0)
			len = (ssize_t)strnlen(buf, (size_t)len);
		if ((size_t)len < off || memcmp(buf, prev, off))
			off = 0;	/* wrapped or restarted */
		while (off < (size_t)len) {
			char *s = buf + off, *nl = memchr(s, '\n', (size_t)len - off);
			size_t n;

			if (!nl)
				break;	/* a line still being written */
			n = (size_t)(nl - s);
			if (n && telem_push_log(&telem, 0, trace_level(s, n), "rpu_app", s, n))
				break;	/* event queue full: retry these lines next time */
			off += n + 1;
		}
		memcpy(prev, buf, off);
	}
	return 0;
}

/* ---- requests from ampctl ---------------------------------------------- */

struct out {
	char *buf;
	size_t len, cap;
};

static void put(struct out *o, const char *fmt, ...)
{
	va_list ap;
	int n;

	for (;;) {
		va_start(ap, fmt);
		n = vsnprintf(o->buf + o->len, o->cap - o->len, fmt, ap);
		va_end(ap);
		if (n >= 0 && o->len + (size_t)n < o->cap)
			break;
		o->cap = o->cap * 2 + (size_t)(n > 0 ? n : 0);
		o->buf = realloc(o->buf, o->cap);
	}
	o->len += (size_t)n;
}

static const char *sstate_name(uint32_t s)
{
	switch (s) {
	case AMP_SSTATE_OFFLINE: return "OFFLINE";
	case AMP_SSTATE_RUNNING: return "RUNNING";
	case AMP_SSTATE_SAFESTOP: return "SAFESTOP";
	case AMP_SSTATE_FAULT: return "FAULT";
	default: return "?";
	}
}

static const char *fault_name(uint32_t f)
{
	switch (f) {
	case SP_FAULT_NONE: return "none";
	case SP_FAULT_LINUX_STALL: return "linux-stalled";
	case SP_FAULT_LINUX_GONE: return "linux-gone";
	case SP_FAULT_FOLLOWING: return "following-error";
	default: return "other";
	}
}

static int req_status(struct out *o, char *msg, size_t n)
{
	struct sp_status s;
	uint32_t sl_state, sl_fault, sl_attach, sl_epoch;
	int peer, rc;

	pthread_mutex_lock(&amp_lock);
	peer = session ? amp_linux_peer(&amp) : AMP_E_PEER_ABSENT;
	sl_state = ocm_rd(&((struct amp_ocm *)ocm)->servo_line.state);
	sl_fault = ocm_rd(&((struct amp_ocm *)ocm)->servo_line.fault);
	sl_attach = ocm_rd(&((struct amp_ocm *)ocm)->servo_line.attach_count);
	sl_epoch = ocm_rd(&((struct amp_ocm *)ocm)->servo_line.epoch);
	pthread_mutex_unlock(&amp_lock);
	put(o, "remoteproc=%s\n", rproc_state());
	put(o, "session=%s epoch=%u\n", session ? "open" : "closed", epoch);
	put(o, "link=%s\n", peer == AMP_OK ? "attached" : amp_strerror(peer));
	put(o, "servo_state=%s fault=0x%08x (%s) servo_epoch=%u attach_count=%u\n",
	    sstate_name(sl_state), sl_fault, fault_name(sl_fault), sl_epoch, sl_attach);
	put(o, "period_us=%u axes=%u wd_limit=%u\n", pset[SP_P_cycle_period_us], pset[SP_P_axes],
	    pset[SP_P_wd_limit]);
	put(o, "params_restored_attach=%u restores=%llu recoveries=%llu recovering=%d\n",
	    restored_attach, (unsigned long long)restores, (unsigned long long)recoveries, recovering);
	{
		char pb[2048];

		prog_format_status(pb, sizeof(pb));
		put(o, "%s", pb);
	}
	if (peer != AMP_OK) {
		snprintf(msg, n, "servo not running (remoteproc %s, link: %s)", rproc_state(),
			 amp_strerror(peer));
		return SE_OFFLINE;
	}
	rc = servo_status(&s, msg, n);
	if (rc)
		return rc;
	put(o, "servo_cycles=%u servo_missed=%u servo_overruns=%u safestops=%u stop_cycles=%u\n",
	    s.cycles, s.missed, s.overruns, s.safestops, s.stop_cycles);
	return SE_OK;
}

static int req_stats(struct out *o, char *msg, size_t n)
{
	struct sp_status s;
	__typeof__(st) c;
	struct amp_stats as;
	struct telem_stats ts;
	uint32_t lcycle;
	int rc;

	pthread_mutex_lock(&amp_lock);
	c = st;
	as = amp.st;
	lcycle = amp.cycle;
	if (telem_on)	/* pushes happen under amp_lock: consistent with st */
		telem_get_stats(&telem, &ts);
	pthread_mutex_unlock(&amp_lock);
	put(o, "linux.wakes=%llu\n", (unsigned long long)c.wakes);
	put(o, "linux.cycles=%llu\n", (unsigned long long)c.cycles);
	put(o, "linux.exchanges=%llu\n", (unsigned long long)c.exchanges);
	put(o, "linux.absent=%llu\n", (unsigned long long)c.absent);
	put(o, "linux.missed_irq=%llu\n", (unsigned long long)c.missed_irq);
	put(o, "linux.uio_skips=%llu\n", (unsigned long long)c.uio_skips);
	put(o, "linux.late=%llu\n", (unsigned long long)c.late);
	put(o, "linux.stalls=%llu\n", (unsigned long long)c.stalls);
	put(o, "linux.last_stall_cycles=%u\nlinux.last_stall_us=%u\n", c.stall_cycles, c.stall_us);
	put(o, "linux.recoveries=%llu\n", (unsigned long long)recoveries);
	put(o, "linux.restores=%llu\n", (unsigned long long)restores);
	put(o, "linux.fb_fresh=%u\nlinux.fb_stale=%u\nlinux.fb_torn=%u\nlinux.fb_missed=%u\nlinux.fb_invalid=%u\n",
	    as.fresh, as.stale, as.torn, as.missed, as.invalid);
	put(o, "linux.peer_late=%u\nlinux.mbox_ok=%u\nlinux.mbox_err=%u\n", as.peer_late, as.mbox_ok, as.mbox_err);
	put(o, "linux.amp_cycle=%u\nlinux.fb_servo_cycle=%u\nlinux.fb_cmd_seq=%u\n", lcycle, c.servo_cycle,
	    c.servo_cmd_seq);
	put(o, "linux.wake_lat_ns.min=%u\nlinux.wake_lat_ns.mean=%llu\nlinux.wake_lat_ns.max=%u\n", c.lat_min,
	    (unsigned long long)(c.lat_n ? c.lat_sum / c.lat_n : 0), c.lat_max);
	put(o, "linux.work_ns.mean=%llu\nlinux.work_ns.max=%u\n",
	    (unsigned long long)(c.cycles ? c.work_sum / c.cycles : 0), c.work_max);
	for (int b = 0; b < HIST_N; b++) {
		if (b < HIST_N - 1)
			put(o, "linux.wake_lat_hist.lt_%uus=%llu\n", hist_edges_us[b], (unsigned long long)c.hist[b]);
		else
			put(o, "linux.wake_lat_hist.ge_%uus=%llu\n", hist_edges_us[b - 1], (unsigned long long)c.hist[b]);
	}
	put(o, "telem.enabled=%d\n", telem_on);
	if (telem_on) {
		put(o, "telem.port=%u\ntelem.pushed=%llu\ntelem.dropped=%llu\ntelem.drained=%llu\n",
		    telem_port(&telem), (unsigned long long)ts.pushed, (unsigned long long)ts.dropped,
		    (unsigned long long)ts.drained);
		put(o, "telem.events=%llu\ntelem.events_dropped=%llu\ntelem.client_lost=%llu\n",
		    (unsigned long long)ts.events, (unsigned long long)ts.events_dropped,
		    (unsigned long long)ts.client_lost);
		put(o, "telem.clients=%u\ntelem.clients_total=%llu\ntelem.bytes_sent=%llu\n"
		       "telem.ring_high_water=%u\n",
		    ts.clients, (unsigned long long)ts.clients_total, (unsigned long long)ts.bytes_sent,
		    ts.ring_high_water);
	}
	{
		char pb[2048];

		prog_format_stats(pb, sizeof(pb));
		put(o, "%s", pb);
	}
	rc = servo_status(&s, msg, n);
	if (rc) {
		put(o, "servo.unavailable=1\n");
		return rc;
	}
	/*
	 * The servo's counters are read through the mailbox after servod's
	 * own: the number of cycles servod handled or counted as missed in
	 * between bounds how far apart the two halves of this snapshot are.
	 */
	pthread_mutex_lock(&amp_lock);
	put(o, "stats.skew_cycles=%llu\n",
	    (unsigned long long)((st.cycles + st.missed_irq) - (c.cycles + c.missed_irq)));
	pthread_mutex_unlock(&amp_lock);
	put(o, "servo.state=%s\nservo.fault=0x%08x\nservo.cycles=%u\nservo.missed=%u\nservo.overruns=%u\n",
	    sstate_name(s.state), s.fault, s.cycles, s.missed, s.overruns);
	put(o, "servo.cmd_fresh=%u\nservo.cmd_stale=%u\nservo.cmd_torn=%u\nservo.cmd_missed=%u\nservo.cmd_invalid=%u\n",
	    s.rx_fresh, s.rx_stale, s.rx_torn, s.rx_missed, s.rx_invalid);
	put(o, "servo.linux_cycle=%u\nservo.attach_count=%u\nservo.period_us=%u\nservo.axes=%u\n", s.linux_cycle,
	    s.attach_count, s.period_us, s.axes);
	put(o, "servo.safestops=%u\nservo.stop_cycles=%u\nservo.mbox_served=%u\n", s.safestops, s.stop_cycles,
	    s.mbox_served);
	put(o, "servo.irq_lat_ns.max=%u\n", s.irq_lat_max_ns);
	put(o, "servo.cost_samples=%u\n", s.samples);
	put(o, "servo.rx_ticks.mean=%u\nservo.rx_ticks.max=%u\n", s.rx_ticks_mean, s.rx_ticks_max);
	put(o, "servo.ctrl_ticks.mean=%u\nservo.ctrl_ticks.max=%u\n", s.ctrl_ticks_mean, s.ctrl_ticks_max);
	put(o, "servo.tx_ticks.mean=%u\nservo.tx_ticks.max=%u\n", s.tx_ticks_mean, s.tx_ticks_max);
	put(o, "servo.cycle_ticks.mean=%u\nservo.cycle_ticks.max=%u\n", s.cycle_ticks_mean, s.cycle_ticks_max);
	return SE_OK;
}

static int req_param(struct out *o, int argc, char **argv, char *msg, size_t n)
{
	char v[48], lo[32], hi[32], df[32];
	uint32_t req[2], resp[2], len, w;
	int32_t status;
	int id, rc;

	if (argc >= 1 && !strcmp(argv[0], "list")) {
		put(o, "%-3s %-16s %-4s %-10s %-12s %-12s %-12s %s\n", "id", "name", "type", "unit", "min", "max",
		    "default", "value");
		for (int i = 0; i < SP_P_COUNT; i++) {
			const struct sp_param_desc *d = &params[i];

			fmt_value(d, pset[i], v, sizeof(v));
			fmt_num(d, d->min, lo, sizeof(lo));
			fmt_num(d, d->max, hi, sizeof(hi));
			fmt_num(d, d->def, df, sizeof(df));
			put(o, "%-3u %-16s %-4s %-10s %-12s %-12s %-12s %s%s\n", d->id, d->name,
			    d->type == SP_T_F32 ? "f32" : d->type == SP_T_I32 ? "i32" : "u32",
			    *d->unit ? d->unit : "-", lo, hi, df, v, (d->flags & SP_F_RO) ? " (ro)" : "");
		}
		return SE_OK;
	}
	if (argc < 2 || (strcmp(argv[0], "get") && strcmp(argv[0], "set")) ||
	    (!strcmp(argv[0], "set") && argc != 3) || (!strcmp(argv[0], "get") && argc != 2)) {
		snprintf(msg, n, "usage: param list | param get NAME | param set NAME VALUE");
		return SE_USAGE;
	}
	id = param_by_name(argv[1]);
	if (id < 0) {
		snprintf(msg, n, "unknown parameter '%s' (see: ampctl param list)", argv[1]);
		return SE_UNKNOWN;
	}
	if (!strcmp(argv[0], "get")) {
		req[0] = (uint32_t)id;
		rc = mbox(SP_CMD_PARAM_GET, req, 4, resp, sizeof(resp), &len, &status, msg, n);
		if (rc)
			return rc;
		if (status || len != 8 || resp[0] != (uint32_t)id) {
			snprintf(msg, n, "%s: %s", params[id].name, sp_strerror(status));
			return SE_SERVO;
		}
		fmt_value(&params[id], resp[1], v, sizeof(v));
		put(o, "%s=%s%s%s\n", params[id].name, v, *params[id].unit ? " " : "", params[id].unit);
		return SE_OK;
	}
	rc = parse_value(&params[id], argv[2], &w, msg, n);
	if (rc)
		return rc;
	req[0] = (uint32_t)id;
	req[1] = w;
	rc = mbox(SP_CMD_PARAM_SET, req, 8, resp, sizeof(resp), &len, &status, msg, n);
	if (rc)
		return rc;
	if (status) {
		snprintf(msg, n, "%s: %s", params[id].name, sp_strerror(status));
		return status == SP_E_RANGE || status == SP_E_READONLY ? SE_VALUE : SE_SERVO;
	}
	if (params[id].flags & SP_F_RESTORE) {
		uint32_t old = pset[id];

		pset[id] = resp[1];
		if (params_save()) {
			pset[id] = old;
			snprintf(msg, n, "cannot store %s: %s (the servo has the new value)", opt.param_path,
				 strerror(errno));
			return SE_IO;
		}
	}
	apply_local((uint32_t)id, resp[1]);
	telem_param((uint32_t)id, resp[1]);
	fmt_value(&params[id], resp[1], v, sizeof(v));
	put(o, "%s=%s%s%s\n", params[id].name, v, *params[id].unit ? " " : "", params[id].unit);
	return SE_OK;
}

static int req_raw(struct out *o, int argc, char **argv, char *msg, size_t n)
{
	static uint32_t req[(AMP_MBOX_CAPACITY + 64) / 4], resp[AMP_MBOX_CAPACITY / 4];
	uint32_t cmd, len, rlen = 0;
	int32_t status;
	int rc;

	if (argc < 2) {
		snprintf(msg, n, "usage: raw COMMAND NBYTES [WORD...]");
		return SE_USAGE;
	}
	cmd = (uint32_t)strtoul(argv[0], 0, 0);
	len = (uint32_t)strtoul(argv[1], 0, 0);
	if (len > sizeof(req)) {
		snprintf(msg, n, "raw: at most %zu bytes", sizeof(req));
		return SE_USAGE;
	}
	memset(req, 0, sizeof(req));
	for (int i = 2; i < argc && (uint32_t)(i - 2) < len / 4u; i++)
		req[i - 2] = (uint32_t)strtoul(argv[i], 0, 0);
	rc = mbox(cmd, req, len, resp, sizeof(resp), &rlen, &status, msg, n);
	if (rc)
		return rc;
	put(o, "status=%d (%s) length=%u\n", status, sp_strerror(status), rlen);
	for (uint32_t i = 0; i < rlen / 4u && i < 16u; i++)
		put(o, "word[%u]=0x%08x\n", i, resp[i]);
	return SE_OK;
}

static void supervise(void);

/* "run FILE": starts the run (program.c), then waits for the verdict of the
 * dry run (whole program checked before any motion) up to 5 s, keeping the
 * supervisor going meanwhile. */
static int req_run(struct out *o, int argc, char **argv, char *msg, size_t n)
{
	int rc, refused = 0;

	if (argc != 1) {
		snprintf(msg, n, "usage: run FILE");
		return SE_USAGE;
	}
	rc = prog_run(argv[0], pset[SP_P_cycle_period_us], msg, n);
	if (rc)
		return rc;
	logm("program %s: checking", argv[0]);
	for (int i = 0; i < 250; i++) {
		struct timespec ts = { 0, 20000000 };

		if (prog_verdict(&refused, msg, n)) {
			if (refused) {
				logm("program refused: %s", msg);
				return SE_PROGRAM;
			}
			logm("program %s", msg);
			put(o, "%s\n", msg);
			return SE_OK;
		}
		supervise();
		nanosleep(&ts, 0);
	}
	put(o, "%s: still checking (ampctl status shows the verdict)\n", argv[0]);
	return SE_OK;
}

static void handle_client(int fd)
{
	char line[512], msg[512] = "", *argv[24], *save = 0, *tok;
	struct out o = { malloc(1024), 0, 1024 };
	int argc = 0, rc = SE_USAGE;
	ssize_t r = 0, got = 0;
	struct pollfd pfd = { fd, POLLIN, 0 };
	char head[600];

	while (got < (ssize_t)sizeof(line) - 1 && poll(&pfd, 1, 1000) > 0) {
		r = read(fd, line + got, sizeof(line) - 1 - (size_t)got);
		if (r <= 0)
			break;
		got += r;
		if (memchr(line, '\n', (size_t)got))
			break;
	}
	line[got] = 0;
	for (tok = strtok_r(line, " \t\r\n", &save); tok && argc < 24; tok = strtok_r(0, " \t\r\n", &save))
		argv[argc++] = tok;
	if (!argc) {
		snprintf(msg, sizeof(msg), "empty request");
	} else if (!strcmp(argv[0], "status")) {
		rc = req_status(&o, msg, sizeof(msg));
	} else if (!strcmp(argv[0], "stats")) {
		rc = req_stats(&o, msg, sizeof(msg));
	} else if (!strcmp(argv[0], "param")) {
		rc = req_param(&o, argc - 1, argv + 1, msg, sizeof(msg));
	} else if (!strcmp(argv[0], "raw")) {
		rc = req_raw(&o, argc - 1, argv + 1, msg, sizeof(msg));
	} else if (!strcmp(argv[0], "run")) {
		rc = req_run(&o, argc - 1, argv + 1, msg, sizeof(msg));
	} else if (!strcmp(argv[0], "stop")) {
		rc = prog_stop(msg, sizeof(msg));
		if (!rc)
			put(&o, "%s\n", msg);
	} else if (!strcmp(argv[0], "resume") || !strcmp(argv[0], "debug")) {
		uint32_t w = 0, len = 0, cmd = SP_CMD_RESUME;
		int32_t status;

		if (!strcmp(argv[0], "debug")) {
			cmd = SP_CMD_DEBUG;
			len = 4;
			if (argc == 2 && !strcmp(argv[1], "hang"))
				w = SP_DEBUG_HANG;
			else if (argc == 2 && !strcmp(argv[1], "crash"))
				w = SP_DEBUG_CRASH;
			else
				cmd = 0;
		}
		if (!cmd) {
			snprintf(msg, sizeof(msg), "usage: debug hang|crash");
		} else {
			rc = mbox(cmd, &w, len, 0, 0, 0, &status, msg, sizeof(msg));
			if (!rc && status) {
				snprintf(msg, sizeof(msg), "%s: %s", argv[0], sp_strerror(status));
				rc = SE_SERVO;
			} else if (!rc) {
				put(&o, "%s: ok\n", argv[0]);
			}
		}
	} else {
		snprintf(msg, sizeof(msg), "unknown request '%s'", argv[0]);
	}
	if (rc == SE_OK)
		snprintf(head, sizeof(head), "OK\n");
	else
		snprintf(head, sizeof(head), "ERR %d %s\n", rc, msg);
	if (write(fd, head, strlen(head)) < 0 || (o.len && write(fd, o.buf, o.len) < 0))
		logm("client write: %s", strerror(errno));
	free(o.buf);
}

/* ---- supervisor ----------------------------------------------------------- */

static void supervise(void)
{
	static int waiting_logged;
	const char *rs = rproc_state();
	char msg[256];
	uint32_t ac;
	int peer;

	if (!session) {
		if (!strcmp(rs, "offline")) {
			pthread_mutex_lock(&amp_lock);
			int rc = amp_linux_init(&amp, (void *)ocm, ocm_size, pset[SP_P_wd_limit]);

			if (rc == AMP_OK) {
				session = 1;
				seen_running = 0;
				epoch = amp.epoch;
				stall_attach = UINT32_MAX;
				restored_attach = 0;
			}
			pthread_mutex_unlock(&amp_lock);
			if (rc == AMP_OK)
				logm("servo offline: region initialised, epoch %u, wd_limit %u; waiting for the servo",
				     epoch, pset[SP_P_wd_limit]);
			else
				logm("amp_linux_init: %s", amp_strerror(rc));
			waiting_logged = 0;
		} else if (!waiting_logged) {
			logm("servo %s but not attached to this servod: waiting until it is offline", rs);
			waiting_logged = 1;
		}
		return;
	}
	if (recovering) {
		struct timespec t;

		clock_gettime(CLOCK_MONOTONIC, &t);
		if (t.tv_sec - recover_t0.tv_sec > 20) {
			logm("recovery: servo not back after 20 s; giving up on it");
			recovering = 0;
		}
	}
	if (!strcmp(rs, "running"))
		seen_running = 1;
	if (!recovering && seen_running && !strcmp(rs, "offline")) {
		/* stopped (not a recovery): a new session for the next start */
		pthread_mutex_lock(&amp_lock);
		session = 0;
		pthread_mutex_unlock(&amp_lock);
		logm("servo went offline");
		return;
	}
	if (atomic_exchange(&stall_pending, 0)) {
		char path[600];

		snprintf(path, sizeof(path), "%s/device/report_crash", rproc_dir);
		logw("servo stalled (heartbeat still for %u cycles): reporting a crash to remoteproc",
		     pset[SP_P_wd_limit]);
		if (write_file(path, "watchdog"))
			logm("%s: %s", path, strerror(errno));
		else {
			recovering = 1;
			recoveries++;
			atomic_store_explicit(&pub.recoveries, recoveries, memory_order_relaxed);
			clock_gettime(CLOCK_MONOTONIC, &recover_t0);
		}
	}
	pthread_mutex_lock(&amp_lock);
	peer = amp_linux_peer(&amp);
	ac = ocm_rd(&amp.ocm->servo_line.attach_count);
	pthread_mutex_unlock(&amp_lock);
	if (peer == AMP_OK && ac != restored_attach && strcmp(rs, "running") == 0) {
		int rc = restore_params(msg, sizeof(msg));

		if (rc == SE_OK) {
			uint64_t c = atomic_load_explicit(&pub.cycles, memory_order_relaxed);

			restored_attach = ac;
			restores++;
			atomic_store_explicit(&pub.restores, restores, memory_order_relaxed);
			if (telem_on) {
				/* the attach as a GAP event (nothing lost: the cycles
				 * in between are on record with their exchange
				 * status): a recovery spans stall detection .. now */
				if (recovering) {
					uint64_t from = atomic_load_explicit(&pub.stall_cycle, memory_order_relaxed);

					telem_push_gap(&telem, 0, from && from <= c ? from : c, c, 0,
						       TELEM_GAP_RECOVERY);
				} else {
					telem_push_gap(&telem, 0, c, c, 0, TELEM_GAP_CONTROLLER_RESTART);
				}
				/* the set just loaded into the servo */
				for (int i = 0; i < SP_P_COUNT; i++)
					if (params[i].flags & SP_F_RESTORE)
						telem_param((uint32_t)i, pset[i]);
			}
			if (recovering)
				logm("recovery complete");
			recovering = 0;
			logm("servo attached (epoch %u, attach_count %u): parameter set loaded", epoch, ac);
		} else {
			restore_errors++;
			logm("parameter restore failed: %s", msg);
		}
	}
}

/* "ADDR:PORT", "[V6ADDR]:PORT" or "off" -> telem_addr / telem_port_opt; 0 ok. */
static int parse_telem_opt(const char *s)
{
	const char *colon;
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
	if (!alen || alen >= sizeof(telem_addr))
		return -1;
	memcpy(telem_addr, s, alen);
	telem_addr[alen] = 0;
	telem_port_opt = (uint16_t)port;
	return 0;
}

static void telemetry_start(void)
{
	struct telem_cfg tc;
	int rc;

	if (!strcmp(opt.telem, "off")) {
		logm("telemetry off");
		return;
	}
	telem_cfg_defaults(&tc);
	tc.listen_addr = telem_addr;
	tc.port = telem_port_opt;
	tc.controller_id = opt.id;
	tc.n_axes = motion_axes;
	tc.cycle_period_ns = period_ns;
	tc.clock_hz = opt.servo_clock_hz;
	tc.drain_interval_us = 10000u;	/* 100 wake-ups/s; the ring holds 4,096 cycles */
	tc.mlock = 1;
	tc.app_counters = telem_counters;
	tc.app_arg = 0;
	rc = telem_init(&telem, &tc);
	if (rc == 0)
		rc = telem_start(&telem);
	if (rc) {
		logw("telemetry off: %s:%u: %s", telem_addr, telem_port_opt, strerror(-rc));
		telem_destroy(&telem);
		return;
	}
	telem_on = 1;
	logm("telemetry on %s:%u (%u axes, ring %u cycles)", telem_addr, telem_port(&telem), tc.n_axes,
	     tc.ring_capacity);
}

static void on_signal(int sig)
{
	(void)sig;
	quit = 1;
}

int main(int argc, char **argv)
{
	struct sched_param sp;
	pthread_attr_t attr;
	pthread_mutexattr_t ma;
	pthread_t th, trace_th;
	int have_trace = 0;
	struct sockaddr_un sa = { .sun_family = AF_UNIX };
	uint32_t size, offs;
	int lfd, rc;

	for (int i = 1; i < argc; i++) {
		if (!strcmp(argv[i], "-s") && i + 1 < argc)
			opt.sock_path = argv[++i];
		else if (!strcmp(argv[i], "-p") && i + 1 < argc)
			opt.param_path = argv[++i];
		else if (!strcmp(argv[i], "-a") && i + 1 < argc)
			opt.amplitude = atof(argv[++i]);
		else if (!strcmp(argv[i], "-f") && i + 1 < argc)
			opt.freq = atof(argv[++i]);
		else if (!strcmp(argv[i], "--ttc-hz") && i + 1 < argc)
			opt.ttc_hz = (uint32_t)strtoul(argv[++i], 0, 0);
		else if (!strcmp(argv[i], "--servo-clock-hz") && i + 1 < argc)
			opt.servo_clock_hz = (uint32_t)strtoul(argv[++i], 0, 0);
		else if (!strcmp(argv[i], "--prio") && i + 1 < argc)
			opt.prio = atoi(argv[++i]);
		else if (!strcmp(argv[i], "--telemetry") && i + 1 < argc)
			opt.telem = argv[++i];
		else if (!strcmp(argv[i], "--id") && i + 1 < argc)
			opt.id = argv[++i];
		else if (!strcmp(argv[i], "--inc-per-mm") && i + 1 < argc)
			opt.prog.inc_per_mm = atof(argv[++i]);
		else if (!strcmp(argv[i], "--vmax") && i + 1 < argc)
			opt.prog.vmax = atof(argv[++i]);
		else if (!strcmp(argv[i], "--amax") && i + 1 < argc)
			opt.prog.amax = atof(argv[++i]);
		else if (!strcmp(argv[i], "--travel") && i + 1 < argc)
			opt.prog.travel = atof(argv[++i]);
		else if (!strcmp(argv[i], "--idle") && i + 1 < argc && !strcmp(argv[i + 1], "hold"))
			opt.prog.idle_hold = 1, i++;
		else if (!strcmp(argv[i], "--idle") && i + 1 < argc && !strcmp(argv[i + 1], "sine"))
			opt.prog.idle_hold = 0, i++;
		else if (!strcmp(argv[i], "-v"))
			opt.verbose = 1;
		else {
			fprintf(stderr, "usage: servod [-s SOCKET] [-p PARAMFILE] [-a AMPLITUDE_INC] [-f FREQ_HZ] "
					"[--ttc-hz HZ] [--servo-clock-hz HZ] [--prio N] "
					"[--telemetry ADDR:PORT|off] [--id NAME] [--inc-per-mm N] [--vmax MM_S] "
					"[--amax MM_S2] [--travel MM] [--idle sine|hold] [-v]\n");
			return 1;
		}
	}
	if (!(opt.prog.inc_per_mm > 0 && opt.prog.vmax > 0 && opt.prog.amax > 0 && opt.prog.travel > 0)) {
		fprintf(stderr, "servod: --inc-per-mm, --vmax, --amax and --travel must be > 0\n");
		return 1;
	}
	if (parse_telem_opt(opt.telem)) {
		fprintf(stderr, "servod: --telemetry wants ADDR:PORT, [ADDR6]:PORT or off, not '%s'\n", opt.telem);
		return 1;
	}
	setvbuf(stderr, 0, _IOLBF, 0);
	params_load();
	period_ns = pset[SP_P_cycle_period_us] * 1000u;
	motion_axes = pset[SP_P_axes];
	opt.prog.period_us = pset[SP_P_cycle_period_us];

	rc = uio_open("ocm-mailbox", &ocm, &size, &offs);
	if (rc < 0) {
		logm("no UIO device for the OCM mailbox (ocm-mailbox)");
		return 1;
	}
	ocm += offs;
	ocm_size = size - offs;
	uio_cycle_fd = uio_open("cycle-interrupt", &ttc, &size, &offs);
	if (uio_cycle_fd < 0) {
		logm("no UIO device for the cycle interrupt (cycle-interrupt)");
		return 1;
	}
	ttc += offs;	/* the node's reg is counter 1's interrupt register */
	ttc -= TTC_ISR1;	/* ... registers addressed from the TTC base */
	if (find_rproc())
		logm("no remoteproc named servo-cpu1 yet");

	pthread_mutexattr_init(&ma);
	pthread_mutexattr_setprotocol(&ma, PTHREAD_PRIO_INHERIT);
	pthread_mutex_init(&amp_lock, &ma);
	prog_init(&opt.prog, &amp_lock);

	signal(SIGINT, on_signal);
	signal(SIGTERM, on_signal);
	signal(SIGPIPE, SIG_IGN);
	if (mlockall(MCL_CURRENT | MCL_FUTURE))
		logm("mlockall: %s", strerror(errno));
	telemetry_start();

	pthread_attr_init(&attr);
	pthread_attr_setinheritsched(&attr, PTHREAD_EXPLICIT_SCHED);
	pthread_attr_setschedpolicy(&attr, SCHED_FIFO);
	sp.sched_priority = opt.prio;
	pthread_attr_setschedparam(&attr, &sp);
	rc = pthread_create(&th, &attr, cycle_thread, 0);
	if (rc) {
		logm("SCHED_FIFO thread: %s; running the cycle at normal priority", strerror(rc));
		rc = pthread_create(&th, 0, cycle_thread, 0);
		if (rc) {
			logm("pthread_create: %s", strerror(rc));
			return 1;
		}
	}

	lfd = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
	snprintf(sa.sun_path, sizeof(sa.sun_path), "%s", opt.sock_path);
	unlink(opt.sock_path);
	if (lfd < 0 || bind(lfd, (struct sockaddr *)&sa, sizeof(sa)) || listen(lfd, 8)) {
		logm("socket %s: %s", opt.sock_path, strerror(errno));
		return 1;
	}
	if (telem_on) {
		rc = pthread_create(&trace_th, 0, trace_thread, 0);
		if (rc)
			logw("firmware trace thread: %s", strerror(rc));
		have_trace = !rc;
	}
	logm("running: cycle thread SCHED_FIFO %d, socket %s, parameters %s, period %u us, %u axes",
	     opt.prio, opt.sock_path, opt.param_path, pset[SP_P_cycle_period_us], pset[SP_P_axes]);

	while (!quit) {
		struct pollfd pfd = { lfd, POLLIN, 0 };

		supervise();
		if (poll(&pfd, 1, 20) > 0) {
			int cfd = accept4(lfd, 0, 0, SOCK_CLOEXEC);

			if (cfd >= 0) {
				handle_client(cfd);
				close(cfd);
			}
		}
	}
	logm("exiting: closing the link (the servo brings its axes to a safe stop)");
	pthread_join(th, 0);	/* the cycle thread sees quit within 100 ms */
	pthread_mutex_lock(&amp_lock);
	if (session)
		amp_linux_close(&amp);
	pthread_mutex_unlock(&amp_lock);
	unlink(opt.sock_path);
	if (have_trace)
		pthread_join(trace_th, 0);
	if (telem_on) {
		/* after the cycle thread: drains the ring, final STATS, closes */
		telem_stop(&telem);
		telem_on = 0;
		telem_destroy(&telem);
	}
	return 0;
}
