// SPDX-License-Identifier: MIT
/*
 * amp_stress - two-sided stress test of amp_lib over shared memory.
 *
 *   amp_stress lockstep [--cycles N] [--mbox M] [--seed S] [--threads]
 *      Linux and servo run as two processes (or two threads with
 *      --threads, for ThreadSanitizer) pinned to different cores, with
 *      random delays on both sides. Every command and feedback record and
 *      every mailbox answer carries values derived from its sequence and
 *      is checked on receipt: any torn, lost, duplicated or reordered
 *      record, or wrong mailbox answer, is counted and fails the run.
 *      Linux prints "linux: I of N cycles" (flushed) every hundredth of the
 *      run: how long it takes depends on the host's load, so a caller
 *      watches for progress rather than timing the whole run.
 *
 *   amp_stress watchdog [--period-us P] [--limit K] [--ticks T]
 *      A third process plays the FPGA: it raises a "cycle" every P us.
 *      After T quiet cycles (no detection allowed), the Linux process is
 *      paused with SIGSTOP: the servo must detect it within K+1 cycles;
 *      after SIGCONT it must see Linux again; then the servo process is
 *      killed: Linux must detect it within K+1 cycles.
 *
 * Prints a summary and exits 0 only if every check held.
 */
#include <errno.h>
#include <inttypes.h>
#include <linux/futex.h>
#include <pthread.h>
#include <sched.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/prctl.h>
#include <sys/syscall.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "amp/amp.h"

/*
 * A wake-up channel between the two sides (test machinery, not amp_lib):
 * seq is a futex word the waiter sleeps on and the other side bumps, then
 * wakes, after it has published something (a command, an answer, a flag);
 * sleeping tells the bumper a FUTEX_WAKE is needed. Both words are only
 * ever accessed with atomics (ThreadSanitizer in --threads mode).
 */
struct chan {
	uint32_t seq;
	uint32_t sleeping;
};

/* Shared between the test processes, NOT part of the OCM layout. */
struct ctl {
	uint32_t done;
	struct chan to_servo;	/* lockstep: Linux published a command / done */
	struct chan to_linux;	/* lockstep: the servo answered / is ready */
	uint32_t mbox_calls;	/* lockstep: mailbox calls Linux has started */
	uint64_t servo_sleeps, servo_timeouts;
	uint32_t tick;		/* watchdog mode: the FPGA cycle counter */
	uint32_t linux_ready, servo_ready;
	uint64_t linux_errors, servo_errors;
	uint64_t servo_cycles, servo_mbox;
	uint32_t servo_detect_tick, servo_recover_tick, linux_detect_tick;
	uint32_t servo_false, linux_false, linux_false_first, servo_false_first;
	uint32_t servo_cycles_to_detect, linux_cycles_to_detect;
	uint32_t stop_tick, cont_tick, kill_tick;
	char first_error[256];
};

static struct amp_ocm *ocm;
static struct ctl *ctl;
static uint64_t n_cycles = 10000000, n_mbox = 1000000;
static uint32_t seed = 12345;
static uint32_t n_axes = AMP_MAX_AXES;

static uint32_t xorshift(uint32_t *s)
{
	uint32_t x = *s;

	x ^= x << 13;
	x ^= x >> 17;
	x ^= x << 5;
	return *s = x;
}

/*
 * Random delay, so that each side is caught at every point of the other's
 * protocol steps: mostly none (200 in 256), sometimes a short spin of up
 * to 1023 pauses (54 in 256), rarely (2 in 256) a sleep of 1-16 us, in
 * which the side leaves its CPU in the middle of a step as a preempted
 * process would. A sleep blocks rather than yields: sched_yield() hands a
 * whole time slice to any other process on a loaded core, which made the
 * run time depend on the host's load.
 */
static void jitter(uint32_t *rng)
{
	uint32_t r = xorshift(rng);
	struct timespec ts = { 0, 1000L * (long)(1u + ((r >> 8) & 15u)) };

	if ((r & 0xff) < 200)
		return;
	if ((r & 0xff) < 254) {
		for (uint32_t i = (r >> 8) & 0x3ff; i; i--)
			AMP_PORT_RELAX();
		return;
	}
	nanosleep(&ts, NULL);
}

static void fail(uint64_t *counter, const char *fmt, uint64_t a, uint64_t b)
{
	if ((*counter)++ == 0 && ctl->first_error[0] == 0)
		snprintf(ctl->first_error, sizeof(ctl->first_error), fmt, a, b);
}

static int32_t cmd_val(uint32_t seq, uint32_t axis, uint32_t field)
{
	return (int32_t)(seq * 2654435761u + axis * 40503u + field * 977u);
}

static int32_t fb_val(uint32_t cmd_seq, uint32_t axis, uint32_t field)
{
	return (int32_t)(cmd_seq * 2246822519u ^ (axis * 3266489917u + field));
}

static void pin(int cpu)
{
	long n = sysconf(_SC_NPROCESSORS_ONLN);
	cpu_set_t set;

	if (n < 2)
		return;
	CPU_ZERO(&set);
	CPU_SET(cpu % (int)n, &set);
	sched_setaffinity(0, sizeof(set), &set);	/* best effort */
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
 * Waiting for the peer, independent of the host's load. The waiter reads
 * chan_epoch() BEFORE it checks its condition; if it must wait, it calls
 * backoff() with that epoch: a bounded spin, then a FUTEX_WAIT on the
 * epoch (it sleeps only if nothing was published since). The publisher
 * calls kick() after publishing. Sleeping, not sched_yield(): a yield on a
 * core shared with a busy process hands it a whole time slice, and the two
 * sides got a few % of a CPU. The futex is not private (the two processes
 * share the page through MAP_SHARED) and has a timeout, so that a lost
 * wake-up can only cost that much; the timeouts are counted.
 */
#define SPIN_LIMIT	256u		/* pauses, ~10 us: longer spins lose more on a loaded core */
#define WAIT_NS		1000000L	/* 1 ms: a wake-up should have come */
#define POLL_NS		20000L		/* 20 us: the peer will publish without a kick */

struct wait_stats {
	uint32_t spins;
	uint64_t sleeps, timeouts;
};

static uint32_t chan_epoch(struct chan *c)
{
	return __atomic_load_n(&c->seq, __ATOMIC_SEQ_CST);
}

static void backoff(struct chan *c, uint32_t epoch, struct wait_stats *w, long timeout_ns)
{
	struct timespec ts = { 0, timeout_ns };

	if (++w->spins < SPIN_LIMIT) {
		AMP_PORT_RELAX();
		return;
	}
	w->spins = 0;
	/* seq_cst on both sides: either kick() sees sleeping set and wakes,
	 * or this load sees its bump and there is no sleep */
	__atomic_store_n(&c->sleeping, 1u, __ATOMIC_SEQ_CST);
	if (chan_epoch(c) == epoch) {
		w->sleeps++;
		if (syscall(SYS_futex, &c->seq, FUTEX_WAIT, epoch, &ts, NULL, 0) != 0 &&
		    errno == ETIMEDOUT)
			w->timeouts++;
	}
	__atomic_store_n(&c->sleeping, 0u, __ATOMIC_SEQ_CST);
}

static void kick(struct chan *c)
{
	__atomic_fetch_add(&c->seq, 1u, __ATOMIC_SEQ_CST);
	if (__atomic_load_n(&c->sleeping, __ATOMIC_SEQ_CST))
		syscall(SYS_futex, &c->seq, FUTEX_WAKE, 1, NULL, NULL, 0);
}

/* Wait on c until cond() holds (cond reads what the kicker published). */
static void wait_until(struct chan *c, struct wait_stats *w, int (*cond)(void))
{
	for (;;) {
		uint32_t epoch = chan_epoch(c);

		if (cond())
			break;
		backoff(c, epoch, w, WAIT_NS);
	}
	w->spins = 0;
}

/* For the waits nobody kicks (attach): block for a moment, do not yield. */
static void pause_briefly(void)
{
	struct timespec ts = { 0, 10000 };

	nanosleep(&ts, NULL);
}

static int servo_is_ready(void)
{
	return ld(&ctl->servo_ready) != 0;
}

static int cycle_answered(void)
{
	return ld(&ocm->cyc_sem.sem) == AMP_SEM_IDLE;
}

/* ---------------- lockstep mode ---------------- */

static void *servo_lockstep(void *arg)
{
	struct amp_servo s;
	struct amp_fb_axis fb[AMP_MAX_AXES];
	struct amp_rx_info rx;
	struct amp_mbox_req req;
	uint8_t buf[AMP_MBOX_CAPACITY];
	uint32_t rng = seed * 7u + 1u, expect = 1;
	struct wait_stats w = { 0, 0, 0 };
	uint64_t errs = 0, mbox = 0, cycles = 0;
	int rc;

	(void)arg;
	pin(1);
	while ((rc = amp_servo_attach(&s, ocm, AMP_OCM_SIZE)) != AMP_OK)
		pause_briefly();
	st(&ctl->servo_ready, 1);
	kick(&ctl->to_linux);
	for (;;) {
		uint32_t epoch = chan_epoch(&ctl->to_servo);

		if (ld(&ctl->done))
			break;
		rc = amp_servo_mbox_poll(&s, &req);
		if (rc == 1) {
			/* answer: the payload reversed, status = command + length */
			for (uint32_t i = 0; i < req.length; i++)
				buf[i] = req.payload[req.length - 1u - i];
			jitter(&rng);
			amp_servo_mbox_respond(&s, (int32_t)(req.command + req.length), buf, req.length);
			mbox++;
		} else if (rc < 0) {
			fail(&errs, "servo: invalid mailbox request (%" PRIu64 ", %" PRIu64 ")", mbox, 0);
		}
		if (ld(&ocm->linux_line.cmd_pub) == s.cmd_seq) {
			/* Linux kicks when it starts a mailbox call, but the
			 * request is posted inside amp_linux_mbox_call, with
			 * no kick after it: until it is here, poll for it */
			backoff(&ctl->to_servo, epoch, &w,
				ld(&ctl->mbox_calls) != (uint32_t)mbox ? POLL_NS : WAIT_NS);
			continue;
		}
		w.spins = 0;
		jitter(&rng);
		amp_servo_cycle_rx(&s, 0, &rx);
		if (rx.status != AMP_RX_FRESH || rx.seq != expect) {
			fail(&errs, "servo: command seq %" PRIu64 " status %" PRIu64, rx.seq, rx.status);
			expect = rx.seq;
		}
		for (uint32_t a = 0; a < s.cmd.n_axes; a++)
			if (s.cmd.axis[a].target_pos != cmd_val(rx.seq, a, 0) ||
			    s.cmd.axis[a].vel_ff != cmd_val(rx.seq, a, 1) ||
			    s.cmd.axis[a].torque_offset != cmd_val(rx.seq, a, 2) ||
			    s.cmd.axis[a].control_word != (uint32_t)cmd_val(rx.seq, a, 3))
				fail(&errs, "servo: command payload wrong at seq %" PRIu64 " axis %" PRIu64, rx.seq, a);
		if (s.cmd.n_axes != n_axes)
			fail(&errs, "servo: n_axes %" PRIu64 " at seq %" PRIu64, s.cmd.n_axes, rx.seq);
		expect++;
		for (uint32_t a = 0; a < n_axes; a++) {
			fb[a].status_word = (uint32_t)fb_val(rx.seq, a, 0);
			fb[a].actual_pos = fb_val(rx.seq, a, 1);
			fb[a].actual_vel = fb_val(rx.seq, a, 2);
			fb[a].current = fb_val(rx.seq, a, 3);
			fb[a].following_error = fb_val(rx.seq, a, 4);
		}
		jitter(&rng);
		amp_servo_cycle_tx(&s, fb, n_axes, rx.seq, 0);
		kick(&ctl->to_linux);
		cycles++;
	}
	ctl->servo_errors = errs + s.st.torn + s.st.invalid + s.st.missed;
	ctl->servo_cycles = cycles;
	ctl->servo_mbox = mbox;
	ctl->servo_sleeps = w.sleeps;
	ctl->servo_timeouts = w.timeouts;
	return NULL;
}

static void *linux_lockstep(void *arg)
{
	struct amp_linux l;
	struct amp_cmd_axis cmd[AMP_MAX_AXES];
	struct amp_rx_info rx;
	uint8_t out[AMP_MBOX_CAPACITY], in[AMP_MBOX_CAPACITY];
	uint32_t rng = seed;
	struct wait_stats w = { 0, 0, 0 };
	uint64_t errs = 0, every = n_mbox ? n_cycles / n_mbox : 0, mbox_done = 0;
	uint64_t step = n_cycles >= 100u ? n_cycles / 100u : 1u;
	int rc;

	(void)arg;
	pin(0);
	/* the servo is attached by the parent's ordering: init first */
	wait_until(&ctl->to_linux, &w, servo_is_ready);
	l = *(struct amp_linux *)arg;
	for (uint64_t i = 1; i <= n_cycles; i++) {
		uint32_t seq = (uint32_t)i;

		/* lockstep: the servo has answered the previous cycle */
		wait_until(&ctl->to_linux, &w, cycle_answered);
		for (uint32_t a = 0; a < n_axes; a++) {
			cmd[a].target_pos = cmd_val(seq, a, 0);
			cmd[a].vel_ff = cmd_val(seq, a, 1);
			cmd[a].torque_offset = cmd_val(seq, a, 2);
			cmd[a].control_word = (uint32_t)cmd_val(seq, a, 3);
		}
		jitter(&rng);
		rc = amp_linux_cycle(&l, cmd, n_axes, 0, &rx);
		kick(&ctl->to_servo);
		if (rc != AMP_OK)
			fail(&errs, "linux: cycle %" PRIu64 " returned %" PRIu64, i, (uint64_t)(int64_t)rc);
		if (i > 1) {
			if (rx.status != AMP_RX_FRESH || l.fb.cmd_seq != seq - 1u)
				fail(&errs, "linux: feedback at cycle %" PRIu64 " status %" PRIu64, i, rx.status);
			for (uint32_t a = 0; a < n_axes; a++)
				if (l.fb.axis[a].actual_pos != fb_val(seq - 1u, a, 1) ||
				    l.fb.axis[a].following_error != fb_val(seq - 1u, a, 4) ||
				    l.fb.axis[a].status_word != (uint32_t)fb_val(seq - 1u, a, 0))
					fail(&errs, "linux: feedback payload wrong at %" PRIu64 " axis %" PRIu64, i, a);
		}
		if (every && i % every == 0) {
			uint32_t len = xorshift(&rng) % (AMP_MBOX_CAPACITY + 1u);
			struct amp_msg req = { .command = seq, .length = len, .data = out };
			struct amp_msg resp = { .capacity = sizeof(in), .data = in };

			for (uint32_t b = 0; b < len; b++)
				out[b] = (uint8_t)xorshift(&rng);
			st(&ctl->mbox_calls, (uint32_t)mbox_done + 1u);
			kick(&ctl->to_servo);
			rc = amp_linux_mbox_call(&l, &req, &resp, 5000000);
			if (rc != AMP_OK || resp.length != len || resp.command != seq ||
			    resp.status != (int32_t)(seq + len))
				fail(&errs, "linux: mailbox call %" PRIu64 " rc %" PRIu64, mbox_done, (uint64_t)(int64_t)rc);
			else
				for (uint32_t b = 0; b < len; b++)
					if (in[b] != out[len - 1u - b]) {
						fail(&errs, "linux: mailbox payload wrong %" PRIu64 " byte %" PRIu64, mbox_done, b);
						break;
					}
			mbox_done++;
		}
		if (i % step == 0) {	/* progress, for a watchdog on the output */
			printf("linux: %" PRIu64 " of %" PRIu64 " cycles\n", i, n_cycles);
			fflush(stdout);
		}
	}
	/* collect the last feedback, then stop the servo */
	wait_until(&ctl->to_linux, &w, cycle_answered);
	for (uint32_t a = 0; a < n_axes; a++) {
		uint32_t seq = (uint32_t)n_cycles + 1u;

		cmd[a].target_pos = cmd_val(seq, a, 0);
		cmd[a].vel_ff = cmd_val(seq, a, 1);
		cmd[a].torque_offset = cmd_val(seq, a, 2);
		cmd[a].control_word = (uint32_t)cmd_val(seq, a, 3);
	}
	amp_linux_cycle(&l, cmd, n_axes, 0, &rx);
	kick(&ctl->to_servo);
	if (rx.status != AMP_RX_FRESH || l.fb.cmd_seq != (uint32_t)n_cycles)
		fail(&errs, "linux: last feedback %" PRIu64 " status %" PRIu64, l.fb.cmd_seq, rx.status);
	/* and let the servo answer that last cycle before it is told to stop */
	wait_until(&ctl->to_linux, &w, cycle_answered);
	errs += l.st.torn + l.st.invalid + l.st.missed;
	ctl->linux_errors = errs;
	printf("linux: cycles %" PRIu64 " fresh %u stale %u torn %u missed %u invalid %u late %u"
	       " mbox ok %u err %u\n", n_cycles, l.st.fresh, l.st.stale, l.st.torn,
	       l.st.missed, l.st.invalid, l.st.peer_late, l.st.mbox_ok, l.st.mbox_err);
	if (l.st.mbox_ok != mbox_done)
		ctl->linux_errors++;
	printf("linux: waits for the servo: %" PRIu64 " sleeps, %" PRIu64 " ended by the 1 ms timeout\n",
	       w.sleeps, w.timeouts);
	st(&ctl->done, 1);
	kick(&ctl->to_servo);
	return NULL;
}

static int run_lockstep(int threads)
{
	struct amp_linux l;
	pid_t pid;

	if (amp_linux_init(&l, ocm, AMP_OCM_SIZE, 1000) != AMP_OK)
		return 2;
	/* sleeps as short as asked (the jitter's few us, the futex
	 * timeouts), not rounded up by the default 50 us timer slack;
	 * inherited by the servo's process or thread. Best effort. */
	(void)prctl(PR_SET_TIMERSLACK, 1000UL, 0UL, 0UL, 0UL);
	if (threads) {
		pthread_t a, b;

		pthread_create(&b, NULL, servo_lockstep, NULL);
		pthread_create(&a, NULL, linux_lockstep, &l);
		pthread_join(a, NULL);
		pthread_join(b, NULL);
	} else {
		pid = fork();
		if (pid == 0) {
			servo_lockstep(NULL);
			_exit(0);
		}
		linux_lockstep(&l);
		waitpid(pid, NULL, 0);
	}
	printf("servo: cycles %" PRIu64 " mailbox answers %" PRIu64 " errors %" PRIu64
	       "; waits for Linux: %" PRIu64 " sleeps, %" PRIu64 " ended by a timeout"
	       " (1 ms, or 20 us for a mailbox request)\n",
	       ctl->servo_cycles, ctl->servo_mbox, ctl->servo_errors,
	       ctl->servo_sleeps, ctl->servo_timeouts);
	if (ctl->servo_cycles != n_cycles + 1)
		ctl->servo_errors++;
	if (ctl->linux_errors || ctl->servo_errors) {
		printf("FAIL: linux errors %" PRIu64 ", servo errors %" PRIu64 ": %s\n",
		       ctl->linux_errors, ctl->servo_errors, ctl->first_error);
		return 1;
	}
	printf("OK: %" PRIu64 " periodic exchanges and %" PRIu64
	       " mailbox transactions, zero torn, lost, duplicated or reordered\n",
	       n_cycles, ctl->servo_mbox);
	return 0;
}

/* ---------------- watchdog mode ---------------- */

static uint32_t period_us = 1000, wd_limit = 20, quiet_ticks = 2000;

/* Like servod's cycle thread: real-time priority where allowed (root or
 * CAP_SYS_NICE), so that other load on a shared machine does not look
 * like a stalled peer. Best effort: the test still runs without it. */
static void realtime(void)
{
	struct sched_param sp = { .sched_priority = 50 };

	if (sched_setscheduler(0, SCHED_FIFO, &sp) != 0)
		fprintf(stderr, "amp_stress: no SCHED_FIFO (%s), running at normal priority\n",
			strerror(errno));
}

static uint32_t wait_tick(uint32_t last)
{
	uint32_t t;

	while ((t = ld(&ctl->tick)) == last && !ld(&ctl->done)) {
		struct timespec ts = { 0, 20000 };

		nanosleep(&ts, NULL);
	}
	return t;
}

static void servo_watchdog(void)
{
	struct amp_servo s;
	struct amp_rx_info rx;
	struct amp_fb_axis fb[1] = { { 0 } };
	uint32_t t = 0, stalled = 0, since = 0;

	pin(1);
	realtime();
	while (amp_servo_attach(&s, ocm, AMP_OCM_SIZE) != AMP_OK)
		pause_briefly();
	st(&ctl->servo_ready, 1);
	kick(&ctl->to_linux);
	while (!ld(&ctl->done)) {
		int rc;

		t = wait_tick(t);
		if (ld(&ctl->stop_tick) && t >= ld(&ctl->stop_tick))
			since++;
		rc = amp_servo_cycle_rx(&s, period_us / 4u, &rx);
		amp_servo_cycle_tx(&s, fb, 1, t, 0);
		if (rc == AMP_E_STALLED && !stalled) {
			stalled = 1;
			if (ld(&ctl->stop_tick) == 0 || t < ld(&ctl->stop_tick)) {
				if (!ctl->servo_false++)
					ctl->servo_false_first = t;
			} else if (!ctl->servo_detect_tick) {
				st(&ctl->servo_detect_tick, t);
				ctl->servo_cycles_to_detect = since;
			}
		} else if (rc == AMP_OK && stalled) {
			stalled = 0;
			if (ctl->servo_detect_tick && !ctl->servo_recover_tick)
				st(&ctl->servo_recover_tick, t);
		}
	}
}

static void linux_watchdog(struct amp_linux *l)
{
	struct amp_rx_info rx;
	struct amp_cmd_axis cmd[1] = { { 0 } };
	uint32_t t = 0, since = 0;

	pin(0);
	realtime();
	while (!ld(&ctl->done)) {
		int rc;

		t = wait_tick(t);
		if (ld(&ctl->kill_tick) && t >= ld(&ctl->kill_tick))
			since++;
		rc = amp_linux_cycle(l, cmd, 1, 0, &rx);
		if (rc == AMP_E_STALLED) {
			if (ld(&ctl->kill_tick) == 0 || t < ld(&ctl->kill_tick)) {
				if (!ctl->linux_false++)
					ctl->linux_false_first = t;
			} else if (!ctl->linux_detect_tick) {
				st(&ctl->linux_detect_tick, t);
				ctl->linux_cycles_to_detect = since;
			}
		}
	}
}

static int run_watchdog(void)
{
	struct amp_linux l;
	pid_t lp, sp;
	struct timespec next;
	struct wait_stats w = { 0, 0, 0 };
	uint32_t t = 0, phase_end, ok = 1;
	int wstatus, servo_reaped = 0;

	if (amp_linux_init(&l, ocm, AMP_OCM_SIZE, wd_limit) != AMP_OK)
		return 2;
	sp = fork();
	if (sp == 0) {
		servo_watchdog();
		_exit(0);
	}
	wait_until(&ctl->to_linux, &w, servo_is_ready);
	lp = fork();
	if (lp == 0) {
		linux_watchdog(&l);
		_exit(0);
	}
	/* the FPGA: a cycle every period_us, on absolute deadlines */
	realtime();
	clock_gettime(CLOCK_MONOTONIC, &next);
	phase_end = quiet_ticks + 4u * wd_limit + quiet_ticks / 4u + 3u * wd_limit;
	for (t = 1; t <= phase_end; t++) {
		next.tv_nsec += (long)period_us * 1000;
		while (next.tv_nsec >= 1000000000L) {
			next.tv_nsec -= 1000000000L;
			next.tv_sec++;
		}
		clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, NULL);
		st(&ctl->tick, t);
		/* the event counts from the cycle in which the process has
		 * really stopped or died (kill() only queues the signal) */
		if (t == quiet_ticks) {
			kill(lp, SIGSTOP);
			waitpid(lp, &wstatus, WUNTRACED);
			st(&ctl->stop_tick, ld(&ctl->tick));
		} else if (t == quiet_ticks + 3u * wd_limit) {
			st(&ctl->cont_tick, t);
			kill(lp, SIGCONT);
		} else if (t == quiet_ticks + 4u * wd_limit + quiet_ticks / 4u) {
			kill(sp, SIGKILL);
			waitpid(sp, &wstatus, 0);
			servo_reaped = 1;
			st(&ctl->kill_tick, ld(&ctl->tick));
		}
	}
	st(&ctl->done, 1);
	waitpid(lp, NULL, 0);
	if (!servo_reaped)
		waitpid(sp, NULL, 0);

	printf("watchdog: period %u us, limit %u cycles\n", period_us, wd_limit);
	printf("  Linux paused at tick %u: servo detected it at tick %u, after %u servo cycles;"
	       " saw Linux again at tick %u\n", ctl->stop_tick, ctl->servo_detect_tick,
	       ctl->servo_cycles_to_detect, ctl->servo_recover_tick);
	printf("  servo killed at tick %u: Linux detected it at tick %u, after %u Linux cycles\n",
	       ctl->kill_tick, ctl->linux_detect_tick, ctl->linux_cycles_to_detect);
	printf("  false detections: servo %u (first at tick %u), Linux %u (first at tick %u)\n",
	       ctl->servo_false, ctl->servo_false_first, ctl->linux_false, ctl->linux_false_first);
	/* bounds: the peer's last beat may land one cycle before or after
	 * the cycle of the stop, so detection comes limit +- 1 cycles later;
	 * earlier would be a false detection, later a missed one */
	if (!ctl->servo_detect_tick || ctl->servo_cycles_to_detect > wd_limit + 1u ||
	    ctl->servo_cycles_to_detect + 1u < wd_limit)
		ok = 0;
	if (!ctl->servo_recover_tick || ctl->servo_recover_tick < ctl->cont_tick)
		ok = 0;
	if (!ctl->linux_detect_tick || ctl->linux_cycles_to_detect > wd_limit + 1u ||
	    ctl->linux_cycles_to_detect + 1u < wd_limit)
		ok = 0;
	if (ctl->servo_false || ctl->linux_false)
		ok = 0;
	printf("%s\n", ok ? "OK: stalls detected within the limit, no false detection"
			  : "FAIL: watchdog expectations not met");
	return ok ? 0 : 1;
}

int main(int argc, char **argv)
{
	const char *mode = argc > 1 ? argv[1] : "lockstep";
	int threads = 0;
	void *mem;

	for (int i = 2; i < argc; i++) {
		const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : "0";

		if (!strcmp(a, "--threads")) {
			threads = 1;
			continue;
		}
		if (!strcmp(a, "--cycles"))
			n_cycles = strtoull(v, NULL, 0);
		else if (!strcmp(a, "--mbox"))
			n_mbox = strtoull(v, NULL, 0);
		else if (!strcmp(a, "--seed"))
			seed = (uint32_t)strtoul(v, NULL, 0) | 1u;
		else if (!strcmp(a, "--axes"))
			n_axes = (uint32_t)strtoul(v, NULL, 0);
		else if (!strcmp(a, "--period-us"))
			period_us = (uint32_t)strtoul(v, NULL, 0);
		else if (!strcmp(a, "--limit"))
			wd_limit = (uint32_t)strtoul(v, NULL, 0);
		else if (!strcmp(a, "--ticks"))
			quiet_ticks = (uint32_t)strtoul(v, NULL, 0);
		else {
			fprintf(stderr, "amp_stress: unknown option %s\n", a);
			return 2;
		}
		i++;
	}
	if (n_axes > AMP_MAX_AXES || (n_mbox && n_mbox > n_cycles) || wd_limit < 2 ||
	    period_us < 100) {
		fprintf(stderr, "amp_stress: bad parameters\n");
		return 2;
	}
	/* one shared mapping: the OCM stand-in, then the test's control page */
	mem = mmap(NULL, 65536, PROT_READ | PROT_WRITE, MAP_SHARED | MAP_ANONYMOUS, -1, 0);
	if (mem == MAP_FAILED) {
		perror("mmap");
		return 2;
	}
	ocm = mem;
	ctl = (struct ctl *)((char *)mem + 32768);
	setvbuf(stdout, NULL, _IONBF, 0);
	if (!strcmp(mode, "lockstep"))
		return run_lockstep(threads);
	if (!strcmp(mode, "watchdog"))
		return run_watchdog();
	fprintf(stderr, "amp_stress: unknown mode %s\n", mode);
	return 2;
}
