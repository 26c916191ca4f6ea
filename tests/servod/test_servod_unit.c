// SPDX-License-Identifier: MIT
/*
 * servod's pieces that need no board, on the host: the session state
 * machine, the setpoint sources (the sine, the program runner taking over
 * from it, the hold before any feedback), the path error on synthetic
 * commands and feedback, and the request table.
 */
#define _GNU_SOURCE
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "context.h"

extern const struct servod_request __start_servod_requests[];
extern const struct servod_request __stop_servod_requests[];

static void test_session(void)
{
	static const struct {
		enum session_state from;
		enum session_event ev;
		enum session_state to;
	} t[] = {
		{ SESSION_CLOSED, SEV_REGION_READY, SESSION_OPEN },
		{ SESSION_CLOSED, SEV_SEEN_RUNNING, SESSION_CLOSED },
		{ SESSION_CLOSED, SEV_SEEN_OFFLINE, SESSION_CLOSED },
		{ SESSION_CLOSED, SEV_CRASH_REPORTED, SESSION_CLOSED },
		{ SESSION_CLOSED, SEV_ATTACHED, SESSION_CLOSED },
		{ SESSION_OPEN, SEV_SEEN_RUNNING, SESSION_RUNNING },
		{ SESSION_OPEN, SEV_SEEN_OFFLINE, SESSION_OPEN },
		{ SESSION_OPEN, SEV_CRASH_REPORTED, SESSION_RECOVERING },
		{ SESSION_OPEN, SEV_REGION_READY, SESSION_OPEN },
		{ SESSION_RUNNING, SEV_SEEN_OFFLINE, SESSION_CLOSED },
		{ SESSION_RUNNING, SEV_SEEN_RUNNING, SESSION_RUNNING },
		{ SESSION_RUNNING, SEV_ATTACHED, SESSION_RUNNING },
		{ SESSION_RUNNING, SEV_CRASH_REPORTED, SESSION_RECOVERING },
		{ SESSION_RECOVERING, SEV_SEEN_OFFLINE, SESSION_RECOVERING },
		{ SESSION_RECOVERING, SEV_SEEN_RUNNING, SESSION_RECOVERING },
		{ SESSION_RECOVERING, SEV_CRASH_REPORTED, SESSION_RECOVERING },
		{ SESSION_RECOVERING, SEV_ATTACHED, SESSION_RUNNING },
		{ SESSION_RECOVERING, SEV_RECOVERY_TIMEOUT, SESSION_RUNNING },
		{ SESSION_RUNNING, SEV_RECOVERY_TIMEOUT, SESSION_RUNNING },
	};
	struct session ss = { .state = SESSION_CLOSED };

	for (size_t i = 0; i < sizeof(t) / sizeof(t[0]); i++)
		CHECK_EQ(session_next(t[i].from, t[i].ev), t[i].to);
	CHECK(!session_open(&ss));
	session_event(&ss, SEV_REGION_READY);
	CHECK(session_open(&ss) && !session_recovering(&ss));
	session_event(&ss, SEV_CRASH_REPORTED);
	CHECK(session_open(&ss) && session_recovering(&ss));
}

static struct servod *new_servod(int idle_hold)
{
	struct servod *sd = aligned_alloc(64, (sizeof(*sd) + 63u) & ~(size_t)63u);

	memset(sd, 0, sizeof(*sd));
	sd->opt.amplitude = 2000.0;
	sd->opt.freq = 0.5;
	sd->opt.prog = (struct prog_opts){ 1000.0, 200.0, 2000.0, 500.0, 1000u, idle_hold };
	sd->period_ns = 1000000u;
	sd->axes = 4;
	pthread_mutex_init(&sd->lock, 0);
	prog_init(&sd->prog, &sd->opt.prog, &sd->lock);
	return sd;
}

static int32_t sine_at(const struct servod *sd, uint32_t cycle, uint32_t axis)
{
	double t = (double)cycle * (double)sd->period_ns * 1e-9;

	return (int32_t)lround(2000.0 * sin(2.0 * M_PI * 0.5 * t + (double)axis * M_PI / 4.0));
}

static void test_sine_then_hold(void)
{
	struct servod *sd = new_servod(0);
	struct amp_cmd_axis cmd[AMP_MAX_AXES];
	const struct setpoint_ops *src;

	sd->amp.cycle = 300;
	src = setpoint_source(sd);
	CHECK(src == &setpoint_sine);
	src->fill(sd, cmd, 4, 1);
	for (uint32_t i = 0; i < 4; i++) {
		CHECK_EQ(cmd[i].target_pos, sine_at(sd, 300, i));
		CHECK_EQ(cmd[i].control_word, AMP_AXIS_ENABLE);
	}
	/* `run` asks for the hold: the program takes over where the sine is */
	atomic_store(&sd->prog.req_hold, 1);
	sd->amp.cycle = 301;
	src = setpoint_source(sd);
	CHECK(src == &setpoint_program);
	src->fill(sd, cmd, 4, 2);
	CHECK_EQ(atomic_load(&sd->prog.mode), PM_HOLD);
	CHECK_EQ(atomic_load(&sd->prog.req_hold), 0);
	for (uint32_t i = 0; i < 4; i++) {
		CHECK_EQ(cmd[i].target_pos, sine_at(sd, 301, i));
		CHECK_EQ(sd->prog.play.hold_pos[i], sine_at(sd, 301, i));
	}
	/* then it holds, axes enabled, whatever the cycle */
	sd->amp.cycle = 800;
	CHECK(setpoint_source(sd) == &setpoint_program);
	setpoint_source(sd)->fill(sd, cmd, 4, 3);
	for (uint32_t i = 0; i < 4; i++) {
		CHECK_EQ(cmd[i].target_pos, sine_at(sd, 301, i));
		CHECK_EQ(cmd[i].control_word, AMP_AXIS_ENABLE);
		CHECK_EQ(cmd[i].vel_ff, 0);
	}
	free(sd);
}

static void test_idle_hold(void)
{
	struct servod *sd = new_servod(1);
	struct amp_cmd_axis cmd[AMP_MAX_AXES];
	struct amp_fb_record fb;

	CHECK(setpoint_source(sd) == &setpoint_program);
	setpoint_source(sd)->fill(sd, cmd, 4, 1);
	for (uint32_t i = 0; i < 4; i++)	/* position unknown: axes disabled */
		CHECK_EQ(cmd[i].control_word, 0);
	memset(&fb, 0, sizeof(fb));
	for (uint32_t i = 0; i < 4; i++)
		fb.axis[i].actual_pos = 100 * (int32_t)i + 7;
	setpoint_program.feedback(sd, AMP_OK, &fb, 4, 0);	/* not fresh: nothing */
	setpoint_source(sd)->fill(sd, cmd, 4, 2);
	CHECK_EQ(cmd[0].control_word, 0);
	setpoint_program.feedback(sd, AMP_OK, &fb, 4, 1);
	setpoint_source(sd)->fill(sd, cmd, 4, 3);
	for (uint32_t i = 0; i < 4; i++) {
		CHECK_EQ(cmd[i].control_word, AMP_AXIS_ENABLE);
		CHECK_EQ(cmd[i].target_pos, 100 * (int32_t)i + 7);
	}
	/* the link lost: disabled again until the next feedback */
	setpoint_program.feedback(sd, AMP_E_PEER_ABSENT, &fb, 4, 0);
	setpoint_source(sd)->fill(sd, cmd, 4, 4);
	CHECK_EQ(cmd[0].control_word, 0);
	free(sd);
}

static void test_path_error(void)
{
	struct path_error pe;
	struct amp_cmd_axis cmd[2];
	struct amp_fb_record fb;
	char *buf = malloc(4096);
	struct out o = { buf, 0, 4096 };

	memset(&pe, 0, sizeof(pe));
	memset(cmd, 0, sizeof(cmd));
	memset(&fb, 0, sizeof(fb));
	path_error_reset(&pe);
	/* a straight line along X, 10 increments per sequence */
	for (uint32_t s = 1; s <= 20; s++) {
		cmd[0].target_pos = (int32_t)s * 10;
		cmd[1].target_pos = 0;
		path_error_command(&pe, s, 5, cmd, 2);
	}
	path_error_start(&pe, 5);
	/* the servo consumed sequence 18, and stands 3 increments off the line */
	fb.cmd_seq = 18;
	fb.axis[0].actual_pos = 180;
	fb.axis[1].actual_pos = 3;
	fb.axis[0].following_error = 0;
	fb.axis[1].following_error = -3;
	path_error_feedback(&pe, &fb, 2);
	CHECK_EQ(pe.samples, 1);
	CHECK(fabs(pe.pe_max - 3.0) < 1e-9);
	CHECK(fabs(pe.fe_max - 3.0) < 1e-9);
	CHECK_EQ(pe.align_mismatch, 0);
	CHECK_EQ(pe.axis_fe_max[1], 3);
	/* before the run's first command: not measured */
	fb.cmd_seq = 4;
	path_error_feedback(&pe, &fb, 2);
	CHECK_EQ(pe.samples, 1);
	/* a skipped sequence is counted */
	fb.cmd_seq = 20;
	fb.axis[0].actual_pos = 200;
	path_error_feedback(&pe, &fb, 2);
	CHECK_EQ(pe.samples, 2);
	CHECK_EQ(pe.cmd_skips, 1);
	/* the run ended at sequence 20: past it, measuring stops */
	path_error_end(&pe);
	fb.cmd_seq = 21;
	path_error_feedback(&pe, &fb, 2);
	CHECK_EQ(pe.measuring, 0);
	path_error_format(&pe, &o, 1000.0);
	CHECK(strstr(o.buf, "motion.samples=2\n") != 0);
	CHECK(strstr(o.buf, "motion.path_err.max_um=3.0\n") != 0);
	CHECK(strstr(o.buf, "motion.cmd_skips=1\n") != 0);
	free(o.buf);
}

static void test_requests(void)
{
	static const char *const names[] = { "status", "stats", "param", "raw", "run", "stop", "resume", "debug" };
	size_t n = (size_t)(__stop_servod_requests - __start_servod_requests);

	CHECK_EQ(n, sizeof(names) / sizeof(names[0]));
	for (size_t i = 0; i < sizeof(names) / sizeof(names[0]); i++) {
		int found = 0;

		for (const struct servod_request *r = __start_servod_requests; r < __stop_servod_requests; r++)
			found += !strcmp(r->name, names[i]) && r->fn;
		CHECK_EQ(found, 1);
	}
}

int main(void)
{
	test_session();
	test_sine_then_hold();
	test_idle_hold();
	test_path_error();
	test_requests();
	return check_summary("servod unit");
}
