/* SPDX-License-Identifier: MIT */
/*
 * motion_wait() is woken when an interpolation lane's release of its last
 * piece ends the run.  The run has ended when the end marker has passed
 * and every lane's input and output ring is empty; a lane commits a
 * piece's last setpoint and only then releases the piece, so the consumer
 * (the sink task, or the send task through motion_next_setpoint()) can take
 * that setpoint in between, find the piece still there and not wake the
 * waiter.  The lane's release is then the last change of the run, and
 * without a wake-up of its own motion_wait() slept until its time-out (the
 * rare 300 s hang of motion_bench in CI).
 *
 * The interleaving is forced, not waited for: this program links an
 * interp.o built with MOTION_TEST_HOOKS (see the Makefile), whose hook
 * holds the lane, just before it releases the program's last piece, until
 * the other worker has passed the end marker and the consumer has taken
 * every setpoint, and the main thread is asleep in motion_wait().  The
 * hook only waits for states, and no timing is asserted but that
 * motion_wait() returns before its 30 s time-out (the hook's 60 s bound
 * only turns a failure into a message rather than a hang).
 */
#define _POSIX_C_SOURCE 200809L
#define MOTION_TEST_HOOKS 1
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "check.h"
#include "interp.h"
#include "pipeline_state.h"
#include "servoamp/mono_clock.h"

/* held: the hook held the lane until the state below; gave_up: it did not
 * come within 60 s */
static atomic_int held, gave_up;

/* Every setpoint taken, the end marker passed, and no piece left but the
 * one lane l is about to release. */
static bool only_release_left(const struct motion *m, const struct interp_lane *l)
{
	if (!atomic_load(&m->ip.done))
		return false;
	for (uint32_t k = 0; k < m->ip.lanes; k++) {
		const struct interp_lane *o = &m->ip.lane[k];
		if (ring_count(&o->out) != 0)
			return false;
		if (ring_count(&o->in) != (o == l ? 1u : 0u))
			return false;
	}
	return true;
}

/* The main thread is asleep in motion_wait(): it counts itself a waiter
 * under end.lock and lets go of the lock only inside the wait. */
static bool waiter_asleep(struct motion *m)
{
	if (atomic_load(&m->end.waiters) == 0)
		return false;
	if (pthread_mutex_trylock(&m->end.lock) != 0)
		return false;
	pthread_mutex_unlock(&m->end.lock);
	return true;
}

static void hold_last_release(const struct interp_lane *l, const struct piece *pc)
{
	struct motion *m = l->ip->m;
	uint64_t t0 = mono_now_us();

	/* the programs below end one motion, at rest: its sample at rest
	 * is the last piece of the run */
	if (!(pc->flags & PIECE_AT_END))
		return;
	while (!only_release_left(m, l) || !waiter_asleep(m)) {
		if (mono_now_us() - t0 > 60000000u) {
			atomic_store(&gave_up, 1);
			return;
		}
		struct timespec ts = { 0, 200000 };
		nanosleep(&ts, NULL);
	}
	atomic_store(&held, 1);
}

static unsigned sends;

static void count_send(void *user, const struct motion_setpoint *sp)
{
	(void)user;
	(void)sp;
	sends++; /* the send task never runs on two workers at once */
}

/* motion_wait()'s time-out.  It returns 0 at its time-out too if the run
 * has ended by then, so a missed wake-up shows as a return at the
 * deadline (the deadline is on the monotonic clock: a return before it
 * was a wake-up). */
#define WAIT_MS 30000u

/* One run on 2 workers (the hook needs a second worker for the accel and
 * consumer tasks while it holds the lane); *woken: motion_wait() returned
 * 0 before its time-out. */
static int held_run(struct motion_config c, const char *prog, bool *woken,
		    struct motion_stats *st)
{
	struct motion *m;
	struct motion_error e;

	atomic_store(&held, 0);
	atomic_store(&gave_up, 0);
	/* whole jobs off: with them, the sink would wait for interp0's
	 * (held) job to end before taking a setpoint short of a batch */
	c.min_job = 1;
	CHECK(motion_create(&c, &m, &e) == 0, "create: %s", e.msg);
	CHECK(motion_load_program(m, prog, strlen(prog)) == 0, "load");
	interp_test_release_hook = hold_last_release;
	CHECK(motion_start(m, 2) == 0, "start");
	uint64_t t0 = mono_now_us();
	int rc = motion_wait(m, WAIT_MS);
	*woken = rc == 0 && mono_now_us() - t0 < WAIT_MS * 1000ull;
	motion_stop(m);
	interp_test_release_hook = NULL;
	motion_get_stats(m, st);
	CHECK(!atomic_load(&gave_up), "the hook never saw every setpoint taken "
	      "and the waiter asleep (setpoints %llu)", (unsigned long long)st->setpoints);
	CHECK(atomic_load(&held), "the last piece's release was not held");
	CHECK(!motion_last_error(m), "error: %s", motion_last_error(m)->msg);
	CHECK(motion_done(m), "the run did not end");
	motion_destroy(m);
	return 0;
}

/* The sink takes the last setpoint before the lane releases its piece. */
static int t_sink_before_release(void)
{
	static const uint32_t lanes[] = { 1, 2, 3 };
	const char *prog = "G21 G90 F600\nG1 X1 Y0.5\nM2\n";

	for (size_t i = 0; i < sizeof(lanes) / sizeof(lanes[0]); i++) {
		struct motion_config c;
		struct motion_stats st;
		bool woken;
		motion_config_default(&c);
		c.drain_sink = true;
		c.interp_lanes = lanes[i];
		c.interp_chunk = 16; /* the motion spans every lane */
		CHECK(held_run(c, prog, &woken, &st) == 0, "%u lanes", lanes[i]);
		CHECK(woken, "%u lanes: motion_wait() not woken by the last release "
		      "(returned at its %u ms time-out, the run ended long before)",
		      lanes[i], WAIT_MS);
		CHECK(st.setpoints > 50, "%u lanes: %llu setpoints", lanes[i],
		      (unsigned long long)st.setpoints);
	}
	return 0;
}

/* The same with the periodic send task as the consumer
 * (motion_next_setpoint()).  A dwell: at rest all along, so a send task
 * that finds no setpoint in time holds still rather than fault, however
 * loaded the machine. */
static int t_send_before_release(void)
{
	const char *prog = "G21 G90\nG4 P0.05\nM2\n";
	struct motion_config c;
	struct motion_stats st;
	bool woken;

	motion_config_default(&c);
	c.send_cb = count_send;
	c.interp_chunk = 8;
	sends = 0;
	CHECK(held_run(c, prog, &woken, &st) == 0, "send task");
	CHECK(woken, "motion_wait() not woken by the last release "
	      "(returned at its %u ms time-out, the run ended long before)", WAIT_MS);
	CHECK(st.setpoints >= 50, "%llu setpoints", (unsigned long long)st.setpoints);
	CHECK(sends >= st.setpoints, "%u sends, %llu setpoints", sends,
	      (unsigned long long)st.setpoints);
	return 0;
}

static const struct test_case cases[] = {
	{ "sink_before_release", t_sink_before_release },
	{ "send_before_release", t_send_before_release },
};

int main(int argc, char **argv)
{
	return test_main(argc, argv, cases, sizeof(cases) / sizeof(cases[0]));
}
