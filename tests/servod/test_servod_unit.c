// SPDX-License-Identifier: MIT
/*
 * servod's pieces that need no board, on the host: the session state
 * machine, the setpoint sources (the sine, the program runner taking over
 * from it, the hold before any feedback), the path error on synthetic
 * commands and feedback, and the request table.
 */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

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
		{ SESSION_RECOVERING, SEV_LATCHED, SESSION_FAULT },
		{ SESSION_FAULT, SEV_RESET, SESSION_RECOVERING },
		{ SESSION_FAULT, SEV_SEEN_RUNNING, SESSION_FAULT },
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
	sd->opt.prog = (struct prog_opts){ 1000.0, 200.0, 2000.0, 500.0, 1000u, idle_hold, PROG_MAX_S_DEFAULT };
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
	fb.n_axes = 4;
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
	static const char *const names[] = { "status", "stats", "param", "raw", "run", "stop", "resume", "debug",
					     "fault" };
	size_t n = (size_t)(__stop_servod_requests - __start_servod_requests);

	CHECK_EQ(n, sizeof(names) / sizeof(names[0]));
	for (size_t i = 0; i < sizeof(names) / sizeof(names[0]); i++) {
		int found = 0;

		for (const struct servod_request *r = __start_servod_requests; r < __stop_servod_requests; r++)
			found += !strcmp(r->name, names[i]) && r->fn;
		CHECK_EQ(found, 1);
	}
}

/* ---- issue 13, item 1: what comes back from the servo is checked ----------- */

/* A scripted servo on the other side of a host buffer standing in for OCM:
 * answers every mailbox request from its own thread, as told. */
static struct {
	struct amp_servo s;
	pthread_t th;
	atomic_int stop;
	/* the answer: status, length in bytes, words (-1 = echo the request's) */
	int32_t status;
	uint32_t len;
	int64_t w[2];
	atomic_uint set_many;	/* parameter sets received */
	atomic_int honest_sets;	/* answer parameter sets {n}, not as scripted */
	/* model: a servo with a parameter store that GET, SET and SET_MANY use
	 * as the firmware does (SET_MANY: all or nothing), not as scripted */
	atomic_int model;
	atomic_uint val[SP_P_COUNT];
	atomic_int many_status;	/* model: SET_MANY refused with this status */
	atomic_int many_garbled;	/* model: SET_MANY answered with no payload */
} fake;

static _Alignas(64) uint8_t fake_ocm[AMP_OCM_SIZE];

static uint32_t payload_word(const struct amp_mbox_req *r, uint32_t i)
{
	const uint8_t *p = r->payload + 4u * i;

	return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

/* The model servo's answer to one request (req: its first two words). */
static void fake_model_serve(const struct amp_mbox_req *r, const uint32_t *req)
{
	uint32_t out[2] = { req[0], 0 }, nw = r->length / 4u;

	switch (r->command) {
	case SP_CMD_PARAM_GET:
	case SP_CMD_PARAM_SET:
		if (req[0] >= SP_P_COUNT) {
			(void)amp_servo_mbox_respond(&fake.s, SP_E_ID, 0, 0);
			return;
		}
		if (r->command == SP_CMD_PARAM_SET)
			atomic_store(&fake.val[req[0]], req[1]);
		out[1] = atomic_load(&fake.val[req[0]]);
		(void)amp_servo_mbox_respond(&fake.s, 0, out, 8);
		return;
	case SP_CMD_PARAM_SET_MANY:
		if (atomic_load(&fake.many_status)) {
			(void)amp_servo_mbox_respond(&fake.s, atomic_load(&fake.many_status), 0, 0);
			return;
		}
		if (atomic_load(&fake.many_garbled)) {
			(void)amp_servo_mbox_respond(&fake.s, 0, 0, 0);
			return;
		}
		for (uint32_t i = 0; i < req[0] && 2u + 2u * i < nw; i++)
			if (payload_word(r, 1u + 2u * i) < SP_P_COUNT)
				atomic_store(&fake.val[payload_word(r, 1u + 2u * i)], payload_word(r, 2u + 2u * i));
		(void)amp_servo_mbox_respond(&fake.s, 0, out, 4);
		return;
	default:
		(void)amp_servo_mbox_respond(&fake.s, SP_E_CMD, 0, 0);
	}
}

static void *fake_servo(void *arg)
{
	(void)arg;
	while (!atomic_load(&fake.stop)) {
		struct amp_mbox_req r;
		uint32_t out[2], req[2] = { 0, 0 };

		if (amp_servo_mbox_poll(&fake.s, &r) != 1) {
			usleep(100);
			continue;
		}
		for (uint32_t i = 0; i < 2 && i < r.length / 4u; i++)
			req[i] = (uint32_t)r.payload[4 * i] | (uint32_t)r.payload[4 * i + 1] << 8 |
				 (uint32_t)r.payload[4 * i + 2] << 16 | (uint32_t)r.payload[4 * i + 3] << 24;
		if (r.command == SP_CMD_PARAM_SET_MANY)
			atomic_fetch_add(&fake.set_many, 1);
		if (atomic_load(&fake.model)) {
			fake_model_serve(&r, req);
			continue;
		}
		if (r.command == SP_CMD_PARAM_SET_MANY && atomic_load(&fake.honest_sets)) {
			(void)amp_servo_mbox_respond(&fake.s, 0, req, 4);
			continue;
		}
		for (int i = 0; i < 2; i++)
			out[i] = fake.w[i] < 0 ? req[i] : (uint32_t)fake.w[i];
		(void)amp_servo_mbox_respond(&fake.s, fake.status, out, fake.len);
	}
	return 0;
}

static void fake_answer(int32_t status, uint32_t len, int64_t w0, int64_t w1)
{
	fake.status = status;
	fake.len = len;
	fake.w[0] = w0;
	fake.w[1] = w1;
}

static struct servod *servod_with_fake_servo(char *param_path)
{
	struct servod *sd = new_servod(0);
	int fd = mkstemp(param_path);

	CHECK(fd >= 0);
	close(fd);
	unlink(param_path);	/* no file yet: the defaults */
	sd->opt.param_path = param_path;
	params_load(sd);
	sd->axes = sd->pset[SP_P_axes];
	sd->period_ns = sd->pset[SP_P_cycle_period_us] * 1000u;
	sd->ocm = fake_ocm;
	sd->ocm_size = sizeof(fake_ocm);
	memset(fake_ocm, 0, sizeof(fake_ocm));
	CHECK_EQ(amp_linux_init(&sd->amp, fake_ocm, sizeof(fake_ocm), 50), AMP_OK);
	CHECK_EQ(amp_servo_attach(&fake.s, fake_ocm, sizeof(fake_ocm)), AMP_OK);
	sd->session.state = SESSION_RUNNING;
	atomic_store(&fake.stop, 0);
	fake_answer(0, 8, -1, -1);
	CHECK_EQ(pthread_create(&fake.th, 0, fake_servo, 0), 0);
	return sd;
}

static void stop_fake_servo(struct servod *sd, const char *param_path)
{
	atomic_store(&fake.stop, 1);
	pthread_join(fake.th, 0);
	unlink(param_path);
	free(sd);
}

static const struct servod_request *request(const char *name)
{
	for (const struct servod_request *r = __start_servod_requests; r < __stop_servod_requests; r++)
		if (!strcmp(r->name, name))
			return r;
	return 0;
}

/* "param ARGS..." through the request table: the SE_* code, msg and body. */
static int param_req(struct servod *sd, const char *a1, const char *a2, const char *a3, char *msg, size_t n,
		     char *body, size_t bn)
{
	char *argv[4] = { "param", (char *)a1, (char *)a2, (char *)a3 };
	char *buf = malloc(4096);
	struct out o = { buf, 0, 4096 };
	int rc;

	msg[0] = 0;
	rc = request("param")->fn(sd, &o, a3 ? 4 : 3, argv, msg, n);
	snprintf(body, bn, "%.*s", (int)o.len, o.buf);
	free(o.buf);
	return rc;
}

static uint32_t f32w(float f)
{
	uint32_t w;

	memcpy(&w, &f, 4);
	return w;
}

static void test_param_answers_checked(void)
{
	char path[] = "/tmp/servod-unit-params.XXXXXX", msg[256], body[512];
	struct servod *sd = servod_with_fake_servo(path);
	uint32_t pset0[SP_P_COUNT];
	unsigned sets;
	int rc;

	memcpy(pset0, sd->pset, sizeof(pset0));
	/* a sane answer is taken */
	CHECK_EQ(param_req(sd, "set", "pos_kp", "61.5", msg, sizeof(msg), body, sizeof(body)), SE_OK);
	CHECK(strstr(body, "pos_kp=61.5") != 0);
	CHECK_EQ(sd->pset[SP_P_pos_kp], f32w(61.5f));
	memcpy(pset0, sd->pset, sizeof(pset0));

	/* a short answer (no value word): refused, nothing read past it */
	fake_answer(0, 4, -1, -1);
	rc = param_req(sd, "set", "axes", "3", msg, sizeof(msg), body, sizeof(body));
	CHECK_EQ(rc, SE_SERVO);
	CHECK(strstr(msg, "axes") != 0);
	CHECK_EQ(sd->axes, 4);
	CHECK_EQ(sd->pset[SP_P_axes], 4);
	/* an answer for another parameter */
	fake_answer(0, 8, SP_P_wd_limit, 3);
	CHECK_EQ(param_req(sd, "set", "axes", "3", msg, sizeof(msg), body, sizeof(body)), SE_SERVO);
	CHECK_EQ(sd->axes, 4);
	/* axes 9 (past AMP_MAX_AXES): refused, never servod's axis count;
	 * the servo may hold anything now, so servod's set is sent again */
	fake_answer(0, 8, -1, AMP_MAX_AXES + 1);
	atomic_store(&fake.honest_sets, 1);
	sets = atomic_load(&fake.set_many);
	CHECK_EQ(param_req(sd, "set", "axes", "3", msg, sizeof(msg), body, sizeof(body)), SE_SERVO);
	CHECK(strstr(msg, "range") != 0);
	CHECK(strstr(msg, "parameter set sent again (axes unchanged)") != 0);
	CHECK_EQ(atomic_load(&fake.set_many), sets + 1);
	atomic_store(&fake.honest_sets, 0);
	CHECK_EQ(sd->axes, 4);
	/* cycle_period_us 0 and 20000: refused, the period stays */
	fake_answer(0, 8, -1, 0);
	CHECK_EQ(param_req(sd, "set", "cycle_period_us", "500", msg, sizeof(msg), body, sizeof(body)), SE_SERVO);
	fake_answer(0, 8, -1, 20000);
	CHECK_EQ(param_req(sd, "set", "cycle_period_us", "500", msg, sizeof(msg), body, sizeof(body)), SE_SERVO);
	CHECK_EQ(sd->period_ns, 1000000u);
	/* wd_limit 0 (servod's watchdog would fall back to its default) */
	fake_answer(0, 8, -1, 0);
	CHECK_EQ(param_req(sd, "set", "wd_limit", "20", msg, sizeof(msg), body, sizeof(body)), SE_SERVO);
	CHECK_EQ(sd->amp.wd.limit, 50);
	/* a float out of range, NaN, infinity */
	fake_answer(0, 8, -1, f32w(5000.0f));
	CHECK_EQ(param_req(sd, "set", "pos_kp", "70", msg, sizeof(msg), body, sizeof(body)), SE_SERVO);
	fake_answer(0, 8, -1, 0x7fc00000u);
	CHECK_EQ(param_req(sd, "set", "pos_kp", "70", msg, sizeof(msg), body, sizeof(body)), SE_SERVO);
	fake_answer(0, 8, -1, 0x7f800000u);
	CHECK_EQ(param_req(sd, "set", "vel_max", "70", msg, sizeof(msg), body, sizeof(body)), SE_SERVO);
	/* an i32 below its minimum */
	fake_answer(0, 8, -1, (uint32_t)-5);
	CHECK_EQ(param_req(sd, "set", "fe_max", "1000", msg, sizeof(msg), body, sizeof(body)), SE_SERVO);
	/* the read-only one answered with another value */
	fake_answer(0, 8, -1, 8);
	CHECK_EQ(param_req(sd, "set", "fine_steps", "4", msg, sizeof(msg), body, sizeof(body)), SE_SERVO);
	/* none of it became servod's state */
	CHECK(!memcmp(pset0, sd->pset, sizeof(pset0)));
	CHECK_EQ(sd->axes, 4);
	CHECK_EQ(sd->period_ns, 1000000u);

	/* param get: the value is checked too (short, other id, out of range) */
	fake_answer(0, 8, -1, 4);
	CHECK_EQ(param_req(sd, "get", "axes", 0, msg, sizeof(msg), body, sizeof(body)), SE_OK);
	CHECK(strstr(body, "axes=4") != 0);
	fake_answer(0, 8, -1, AMP_MAX_AXES + 1);
	CHECK_EQ(param_req(sd, "get", "axes", 0, msg, sizeof(msg), body, sizeof(body)), SE_SERVO);
	CHECK(strstr(msg, "range") != 0);
	CHECK(!strstr(body, "axes="));
	fake_answer(0, 4, -1, 4);
	CHECK_EQ(param_req(sd, "get", "axes", 0, msg, sizeof(msg), body, sizeof(body)), SE_SERVO);
	CHECK(!strstr(msg, ": ok"));	/* not "axes: ok" for a short answer */

	/* the parameter set at an attach: the answer {n} is checked */
	fake_answer(0, 4, -1, 0);
	CHECK_EQ(params_restore(sd, msg, sizeof(msg)), SE_OK);
	fake_answer(0, 0, -1, 0);
	CHECK_EQ(params_restore(sd, msg, sizeof(msg)), SE_SERVO);
	fake_answer(0, 4, 3, 0);
	CHECK_EQ(params_restore(sd, msg, sizeof(msg)), SE_SERVO);
	stop_fake_servo(sd, path);
}

/* ---- issue 20, item 6: a parameter set the file cannot take --------------- */

static void read_text(const char *path, char *buf, size_t n)
{
	FILE *f = fopen(path, "r");
	size_t r = f ? fread(buf, 1, n - 1, f) : 0;

	buf[r] = 0;
	if (f)
		fclose(f);
}

/* servod's set, period, watchdog and axis count are what the model servo
 * holds: the two sides agree */
static int sides_agree(const struct servod *sd)
{
	for (int i = 0; i < SP_P_COUNT; i++)
		if ((param_desc[i].flags & SP_F_RESTORE) && atomic_load(&fake.val[i]) != sd->pset[i])
			return 0;
	return sd->period_ns == sd->pset[SP_P_cycle_period_us] * 1000u && sd->axes == sd->pset[SP_P_axes] &&
	       sd->amp.wd.limit == sd->pset[SP_P_wd_limit];
}

/*
 * The servo takes a new value, then servod cannot store its file (ENOSPC:
 * the temp file is /dev/full; EISDIR: the file's name is a directory).
 * The servo used to keep the new value while servod kept the old one (and
 * its old period, watchdog, axis count). Now the set is all or nothing:
 * servod's set goes back to the servo, `param get` says the old value, the
 * file is unchanged. A servo that refuses to go back is followed by servod
 * (and the message says the file differs); one that gives no usable answer
 * gets servod's set again from the supervisor's params_resend().
 */
static void test_param_save_failure(void)
{
	static const struct {
		const char *name, *value;
		int id;
	} t[] = {
		{ "cycle_period_us", "2000", SP_P_cycle_period_us },
		{ "wd_limit", "20", SP_P_wd_limit },
		{ "axes", "3", SP_P_axes },
		{ "pos_kp", "70", SP_P_pos_kp },
	};
	char path[] = "/tmp/servod-unit-params.XXXXXX", tmp[64], keep[64], msg[512], body[512];
	char file0[1024], file1[1024];
	struct servod *sd = servod_with_fake_servo(path);
	struct stat st;

	snprintf(tmp, sizeof(tmp), "%s.tmp", path);
	snprintf(keep, sizeof(keep), "%s.keep", path);
	CHECK_EQ(amp_linux_set_wd_limit(&sd->amp, sd->pset[SP_P_wd_limit]), AMP_OK);
	for (int i = 0; i < SP_P_COUNT; i++)	/* attached: the servo has servod's set */
		atomic_store(&fake.val[i], sd->pset[i]);
	atomic_store(&fake.model, 1);
	CHECK_EQ(param_req(sd, "set", "pos_kp", "61.5", msg, sizeof(msg), body, sizeof(body)), SE_OK);
	CHECK(sides_agree(sd));
	read_text(path, file0, sizeof(file0));
	CHECK(strstr(file0, "pos_kp 61.5\n") != 0);

	/* ENOSPC on the write */
	for (size_t i = 0; i < sizeof(t) / sizeof(t[0]); i++) {
		uint32_t was = sd->pset[t[i].id];

		CHECK_EQ(symlink("/dev/full", tmp), 0);
		CHECK_EQ(param_req(sd, "set", t[i].name, t[i].value, msg, sizeof(msg), body, sizeof(body)), SE_IO);
		CHECK(strstr(msg, "No space left on device") != 0);
		CHECK(strstr(msg, "nothing changed") != 0);
		printf("  %s %s: %s\n", t[i].name, t[i].value, msg);
		CHECK_EQ(sd->pset[t[i].id], was);
		CHECK(sides_agree(sd));
		CHECK(lstat(tmp, &st) != 0 && errno == ENOENT);	/* no temp file left */
		CHECK_EQ(param_req(sd, "get", t[i].name, 0, msg, sizeof(msg), body, sizeof(body)), SE_OK);
		CHECK(strstr(body, t[i].name) != 0 && !strstr(body, t[i].value));
		read_text(path, file1, sizeof(file1));
		CHECK(!strcmp(file0, file1));
	}
	unlink(tmp);

	/* EISDIR on the rename: the file's name is a directory now */
	CHECK_EQ(rename(path, keep), 0);
	CHECK_EQ(mkdir(path, 0700), 0);
	CHECK_EQ(param_req(sd, "set", "axes", "2", msg, sizeof(msg), body, sizeof(body)), SE_IO);
	CHECK(strstr(msg, "Is a directory") != 0 && strstr(msg, "nothing changed") != 0);
	CHECK_EQ(sd->axes, 4);
	CHECK(sides_agree(sd));
	CHECK(stat(tmp, &st) != 0 && errno == ENOENT);

	/* the servo refuses to go back (it applied none of it): servod follows
	 * the servo, and says the file still has the old value */
	atomic_store(&fake.many_status, SP_E_OVERLOAD);
	CHECK_EQ(param_req(sd, "set", "cycle_period_us", "2000", msg, sizeof(msg), body, sizeof(body)), SE_IO);
	atomic_store(&fake.many_status, 0);
	CHECK(strstr(msg, "the servo and servod use cycle_period_us=2000, the file still says 1000") != 0);
	printf("  refused: %s\n", msg);
	CHECK_EQ(sd->pset[SP_P_cycle_period_us], 2000);
	CHECK_EQ(sd->period_ns, 2000000u);
	CHECK(sides_agree(sd));

	/* no usable answer: servod keeps its set, says so, and the supervisor
	 * sends it again until the servo has it */
	atomic_store(&fake.many_garbled, 1);
	CHECK_EQ(param_req(sd, "set", "wd_limit", "30", msg, sizeof(msg), body, sizeof(body)), SE_IO);
	CHECK(strstr(msg, "the servo may use 30") != 0);
	printf("  no answer: %s\n", msg);
	CHECK_EQ(sd->session.params_resend, 1);
	CHECK_EQ(sd->pset[SP_P_wd_limit], 10);
	CHECK_EQ(atomic_load(&fake.val[SP_P_wd_limit]), 30);
	params_resend(sd);	/* still no answer */
	CHECK_EQ(sd->session.params_resend, 1);
	atomic_store(&fake.many_garbled, 0);
	sd->session.resend_ns = 0;	/* as if a second had passed */
	params_resend(sd);
	CHECK_EQ(sd->session.params_resend, 0);
	CHECK(sides_agree(sd));

	/* the file writable again: the next set is stored */
	rmdir(path);
	CHECK_EQ(rename(keep, path), 0);
	CHECK_EQ(param_req(sd, "set", "axes", "2", msg, sizeof(msg), body, sizeof(body)), SE_OK);
	read_text(path, file1, sizeof(file1));
	CHECK(strstr(file1, "axes 2\n") != 0 && strstr(file1, "cycle_period_us 2000\n") != 0);
	CHECK(sides_agree(sd));
	atomic_store(&fake.model, 0);
	stop_fake_servo(sd, path);
}

/* The cycle's pieces never index past AMP_MAX_AXES, whatever n they get. */
static void test_cycle_bounds(void)
{
	struct servod *sd = new_servod(0);
	struct amp_cmd_axis cmd[AMP_MAX_AXES + 2];
	struct amp_fb_record fb;
	struct cycle_stats st;
	struct cycle_wake w = { 1, 1000000, 5000 };

	memset(cmd, 0, sizeof(cmd));
	memset(&fb, 0, sizeof(fb));
	/* the sine -> hold hand-over with n = AMP_MAX_AXES + 2 */
	atomic_store(&sd->prog.req_hold, 1);
	prog_cycle(&sd->prog, cmd, AMP_MAX_AXES + 2, 1);
	prog_cycle(&sd->prog, cmd, AMP_MAX_AXES + 2, 2);
	CHECK_EQ(sd->prog.play.have_hold, 1);
	CHECK_EQ(sd->prog.play.resync, 0);
	fb.n_axes = AMP_MAX_AXES;
	sd->prog.play.resync = 1;
	prog_feedback(&sd->prog, AMP_OK, &fb, AMP_MAX_AXES + 2, 1);

	/* a period of 0 in the counters: no division by zero */
	memset(&st, 0, sizeof(st));
	cycle_stats_wake(&st, &w, 1000000u);
	w.t_ns += 3000000;
	cycle_stats_wake(&st, &w, 0);
	CHECK_EQ(st.wakes, 2);
	/* an event time that goes back (the latency read across a counter
	 * restart) misses nothing; the Studio test on the board showed
	 * servod.missed_irq = 18446744074815, ~2^64 / 1 ms, before */
	w.t_ns += 1000000;
	w.lat_ns = 900000;
	cycle_stats_wake(&st, &w, 1000000u);
	w.t_ns += 100000;
	w.lat_ns = 0;	/* event 100 us after the last wake, 1 ms after its event */
	cycle_stats_wake(&st, &w, 1000000u);
	w.t_ns += 50000;
	w.lat_ns = 900000;	/* this event: before the last one */
	cycle_stats_wake(&st, &w, 1000000u);
	CHECK_EQ(st.missed_irq, 0);
	w.t_ns += 3000000;
	w.lat_ns = 0;	/* then 3 periods on: 2 missed, counted */
	cycle_stats_wake(&st, &w, 1000000u);
	CHECK(st.missed_irq >= 1 && st.missed_irq <= 3);
	free(sd);
}

/* Feedback that covers fewer axes than servod commands is no hold position
 * for the axes it does not cover. */
static void test_feedback_axis_count(void)
{
	struct servod *sd = new_servod(1);
	struct amp_cmd_axis cmd[AMP_MAX_AXES];
	struct amp_fb_record fb;

	memset(&fb, 0, sizeof(fb));
	for (uint32_t i = 0; i < 4; i++)
		fb.axis[i].actual_pos = 1000 + (int32_t)i;
	fb.n_axes = 2;	/* the servo says: 2 axes */
	setpoint_program.feedback(sd, AMP_OK, &fb, 4, 1);
	setpoint_source(sd)->fill(sd, cmd, 4, 1);
	CHECK_EQ(sd->prog.play.have_hold, 0);
	for (uint32_t i = 0; i < 4; i++)	/* still disabled: position unknown */
		CHECK_EQ(cmd[i].control_word, 0);
	fb.n_axes = 4;
	setpoint_program.feedback(sd, AMP_OK, &fb, 4, 1);
	setpoint_source(sd)->fill(sd, cmd, 4, 2);
	for (uint32_t i = 0; i < 4; i++) {
		CHECK_EQ(cmd[i].control_word, AMP_AXIS_ENABLE);
		CHECK_EQ(cmd[i].target_pos, 1000 + (int32_t)i);
	}
	free(sd);
}

/* Issue 13, item 3: a running program ends when the servo reports a fault
 * (or a garbled state word), and a fault that lasts wd_limit cycles is
 * reported for recovery like a stall, once per attach. */
static void test_peer_error(void)
{
	struct servod *sd = new_servod(1);
	struct amp_fb_record fb;
	struct cycle_stats st;

	memset(&fb, 0, sizeof(fb));
	fb.n_axes = 4;
	setpoint_program.feedback(sd, AMP_OK, &fb, 4, 1);	/* hold known */
	atomic_store(&sd->prog.mode, PM_RUN);
	atomic_store(&sd->prog.result, PR_RUNNING);
	setpoint_program.feedback(sd, AMP_E_PEER_ERROR, &fb, 4, 1);
	CHECK_EQ(atomic_load(&sd->prog.mode), PM_HOLD);
	CHECK_EQ(atomic_load(&sd->prog.result), PR_FAULT);
	CHECK(atomic_load(&sd->prog.link_lost) != 0);
	CHECK_EQ(sd->prog.play.have_hold, 0);	/* axes disabled until the servo is sane */
	free(sd);

	memset(&st, 0, sizeof(st));
	cycle_stats_new_session(&st);
	for (int i = 1; i < 10; i++)
		CHECK_EQ(cycle_stats_peer_error(&st, AMP_E_PEER_ERROR, 10, 1, 1000u * (uint64_t)i), 0);
	CHECK_EQ(cycle_stats_peer_error(&st, AMP_E_PEER_ERROR, 10, 1, 10000), 1);
	CHECK_EQ(cycle_stats_peer_error(&st, AMP_E_PEER_ERROR, 10, 1, 11000), 0);	/* once */
	CHECK_EQ(st.stalls, 1);
	CHECK_EQ(st.peer_errors, 11);
	/* a sane cycle restarts the count; the restarted servo gets its own report */
	CHECK_EQ(cycle_stats_peer_error(&st, AMP_OK, 10, 2, 12000), 0);
	for (int i = 1; i < 10; i++)
		CHECK_EQ(cycle_stats_peer_error(&st, AMP_E_PEER_ERROR, 10, 2, 12000), 0);
	CHECK_EQ(cycle_stats_peer_error(&st, AMP_OK, 10, 2, 12000), 0);
	CHECK_EQ(cycle_stats_peer_error(&st, AMP_E_PEER_ERROR, 10, 2, 12000), 0);
	for (int i = 1; i < 10; i++)
		(void)cycle_stats_peer_error(&st, AMP_E_PEER_ERROR, 10, 2, 12000);
	CHECK_EQ(st.stalls, 2);
}

/* ---- issue 13, item 7: the control socket never makes the main thread wait ---- */

static int client_connect(const char *path)
{
	struct sockaddr_un sa = { .sun_family = AF_UNIX };
	int fd = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);

	snprintf(sa.sun_path, sizeof(sa.sun_path), "%s", path);
	if (fd >= 0 && connect(fd, (struct sockaddr *)&sa, sizeof(sa))) {
		close(fd);
		return -1;
	}
	return fd;
}

/* What the client has received so far without waiting: bytes (answer in
 * buf), 0 at EOF, -1 nothing yet. */
static ssize_t client_take(int fd, char *buf, size_t n)
{
	ssize_t r = recv(fd, buf, n - 1, MSG_DONTWAIT);

	buf[r > 0 ? r : 0] = 0;
	return r < 0 && errno == EAGAIN ? -1 : r;
}

/* Serves until the client has an answer (bounded); returns its length. */
static ssize_t serve_until_answer(struct servod *sd, int fd, char *buf, size_t n)
{
	ssize_t r = -1;

	for (int i = 0; i < 500 && r < 0; i++) {
		control_serve(sd, 20);
		r = client_take(fd, buf, n);
	}
	return r;
}

static struct servod *servod_listening(char *path)
{
	struct servod *sd = new_servod(0);
	int fd = mkstemp(path);

	CHECK(fd >= 0);
	close(fd);
	unlink(path);
	sd->opt.sock_path = path;
	CHECK_EQ(control_listen(sd), 0);
	return sd;
}

static void test_control_trickle(void)
{
	char path[] = "/tmp/servod-unit-sock.XXXXXX", ans[256];
	struct servod *sd = servod_listening(path);
	struct stat st;
	int a, b;

	CHECK(stat(path, &st) == 0 && (st.st_mode & 0777) == 0666);
	/* A trickles its request, B sends a whole one: B is answered while A
	 * has not finished; A is answered once its line is complete */
	a = client_connect(path);
	CHECK(a >= 0);
	CHECK_EQ(write(a, "sto", 3), 3);
	control_serve(sd, 0);
	control_serve(sd, 0);
	b = client_connect(path);
	CHECK(b >= 0);
	CHECK_EQ(write(b, "stop\n", 5), 5);
	CHECK(serve_until_answer(sd, b, ans, sizeof(ans)) > 0);
	CHECK(!strncmp(ans, "OK\n", 3));
	CHECK_EQ(client_take(a, ans, sizeof(ans)), -1);	/* A: nothing yet, not closed */
	CHECK_EQ(write(a, "p\n", 2), 2);
	CHECK(serve_until_answer(sd, a, ans, sizeof(ans)) > 0);
	CHECK(!strncmp(ans, "OK\n", 3));
	if (strncmp(ans, "OK\n", 3))
		printf("  trickled request answered: %s", ans);
	close(a);
	close(b);
	/* a line never completed: answered and closed at the deadline, which
	 * bytes arriving do not extend */
	a = client_connect(path);
	CHECK(a >= 0);
	CHECK_EQ(write(a, "s", 1), 1);
	for (int i = 0; i < 8; i++) {
		struct timespec ts = { 0, 150000000 };

		control_serve(sd, 0);
		nanosleep(&ts, 0);
		if (send(a, "t", 1, MSG_NOSIGNAL) != 1)
			break;
	}
	CHECK(serve_until_answer(sd, a, ans, sizeof(ans)) > 0);
	CHECK(!strncmp(ans, "ERR 1 no whole request line", 27));
	close(a);
	control_close(sd);
	free(sd);
}

/* Only root and servod's own uid: another uid is refused with ERR 11. */
static void test_control_peer(void)
{
	char path[] = "/tmp/servod-unit-sock.XXXXXX", ans[256];
	struct servod *sd;
	pid_t pid;
	int status = -1;

	CHECK(control_peer_allowed(0, 1000));
	CHECK(control_peer_allowed(1000, 1000));
	CHECK(!control_peer_allowed(1001, 1000));
	CHECK(!control_peer_allowed(1001, 0));
	if (geteuid() != 0) {
		printf("  (not root: a connection from another uid is not tried)\n");
		return;
	}
	sd = servod_listening(path);
	pid = fork();
	if (pid == 0) {	/* another uid asks for "stop" */
		int fd;

		if (setresgid(65534, 65534, 65534) || setresuid(65534, 65534, 65534))
			_exit(3);
		fd = client_connect(path);
		if (fd < 0)
			_exit(2);
		/* servod may have refused and closed already: then its answer waits */
		(void)send(fd, "stop\n", 5, MSG_NOSIGNAL);
		shutdown(fd, SHUT_WR);
		ssize_t r = read(fd, ans, sizeof(ans) - 1);

		ans[r > 0 ? r : 0] = 0;
		_exit(!strncmp(ans, "ERR 11 permission denied", 24) ? 0 : 1);
	}
	CHECK(pid > 0);
	for (int i = 0; i < 500 && waitpid(pid, &status, WNOHANG) == 0; i++)
		control_serve(sd, 20);
	CHECK(WIFEXITED(status) && WEXITSTATUS(status) == 0);
	if (!WIFEXITED(status) || WEXITSTATUS(status))
		printf("  other uid's client: status 0x%x (2: could not connect, 1: not refused)\n", status);
	control_close(sd);
	free(sd);
}

/* ---- issue 13, item 8: run FILE ------------------------------------------------ */

static struct servod *servod_holding(void)
{
	struct servod *sd = new_servod(1);
	struct amp_fb_record fb;

	memset(&fb, 0, sizeof(fb));
	fb.n_axes = 4;
	setpoint_program.feedback(sd, AMP_OK, &fb, 4, 1);	/* hold position known */
	return sd;
}

static void write_file(const char *path, const char *text)
{
	FILE *f = fopen(path, "w");

	CHECK(f != 0);
	fputs(text, f);
	fclose(f);
}

/* Waits (bounded: 120 s) for the dry run's verdict: 1 refused, 0 ok, -1 none. */
static int wait_verdict(struct servod *sd, char *msg, size_t n)
{
	int refused = 0;

	for (int i = 0; i < 12000; i++) {
		struct timespec ts = { 0, 10000000 };

		if (prog_verdict(&sd->prog, &refused, msg, n))
			return refused;
		nanosleep(&ts, 0);
	}
	return -1;
}

static void end_feeder(struct servod *sd)
{
	if (sd->prog.feeder_alive) {
		atomic_store(&sd->prog.feeder_abort, 1);
		pthread_join(sd->prog.feeder_th, 0);
		sd->prog.feeder_alive = 0;
	}
}

static void test_run_fifo_refused(void)
{
	char dir[] = "/tmp/servod-unit-run.XXXXXX", fifo[64], good[64], msg[512];
	struct servod *sd = servod_holding();

	CHECK(mkdtemp(dir) != 0);
	snprintf(fifo, sizeof(fifo), "%s/fifo.nc", dir);
	snprintf(good, sizeof(good), "%s/good.nc", dir);
	CHECK_EQ(mkfifo(fifo, 0600), 0);
	write_file(good, "G21 G90\nG1 X1 F600\nM2\n");
	CHECK_EQ(prog_run(&sd->prog, fifo, 1000, msg, sizeof(msg)), SE_PROGRAM);
	CHECK(strstr(msg, "not a regular file") != 0);
	CHECK_EQ(prog_run(&sd->prog, dir, 1000, msg, sizeof(msg)), SE_PROGRAM);
	/* and the next run works */
	CHECK_EQ(prog_run(&sd->prog, good, 1000, msg, sizeof(msg)), SE_OK);
	CHECK_EQ(wait_verdict(sd, msg, sizeof(msg)), 0);
	end_feeder(sd);
	unlink(fifo);
	unlink(good);
	rmdir(dir);
	free(sd);
}

/* A program longer than opt.max_s (a dwell, a feed near 0) is refused by
 * the dry run, with its line. */
static void test_run_dry_run_bounded(void)
{
	static const struct {
		const char *text;
		const char *where;
	} t[] = {
		{ "G4 P999999999\nM2\n", ":1: error: the program runs longer than 3600 s" },
		{ "G21 G90\nF0.000001\nG1 X1\nM2\n", ":3: error: the program runs longer than 3600 s" },
	};
	char path[] = "/tmp/servod-unit-prog.XXXXXX", msg[512];
	int fd = mkstemp(path);

	CHECK(fd >= 0);
	close(fd);
	for (size_t i = 0; i < sizeof(t) / sizeof(t[0]); i++) {
		struct servod *sd = servod_holding();

		write_file(path, t[i].text);
		CHECK_EQ(prog_run(&sd->prog, path, 1000, msg, sizeof(msg)), SE_OK);
		CHECK_EQ(wait_verdict(sd, msg, sizeof(msg)), 1);
		CHECK(strstr(msg, t[i].where) != 0);
		printf("  %s", msg);
		printf("\n");
		CHECK_EQ(atomic_load(&sd->prog.mode), PM_HOLD);
		end_feeder(sd);
		free(sd);
	}
	unlink(path);
}

/* The program that runs is the program that was checked: the file changed
 * after the dry run (its last move made malformed) changes nothing. */
static void test_run_checked_text_runs(void)
{
	char path[] = "/tmp/servod-unit-prog.XXXXXX", msg[512];
	struct servod *sd = servod_holding();
	struct amp_cmd_axis cmd[AMP_MAX_AXES];
	int fd = mkstemp(path);
	FILE *f = fdopen(fd, "w");
	long tail;
	uint32_t seq = 1;

	CHECK(f != 0);
	fputs("G21 G90\nG1 X100 F600\n", f);	/* 10 s: the setpoint queue fills */
	for (int i = 0; i < 10000; i++)
		fputs(i & 1 ? "G1 X100\n" : "G1 X100.001\n", f);
	tail = ftell(f);
	fputs("G1 X0\nM2\n", f);
	fclose(f);
	CHECK_EQ(prog_run(&sd->prog, path, 1000, msg, sizeof(msg)), SE_OK);
	CHECK_EQ(wait_verdict(sd, msg, sizeof(msg)), 0);
	/* the file's last move is now malformed */
	fd = open(path, O_WRONLY);
	CHECK_EQ(pwrite(fd, "G1 Q0\n", 6, tail), 6);
	close(fd);
	memset(cmd, 0, sizeof(cmd));
	for (long i = 0; i < 5000000 && atomic_load(&sd->prog.mode) != PM_HOLD; i++) {
		if (atomic_load(&sd->prog.mode) == PM_RUN && !ring_count(&sd->prog.queue) &&
		    !atomic_load(&sd->prog.feeder_done)) {
			usleep(100);	/* let the feeder fill the queue */
			continue;
		}
		pthread_mutex_lock(&sd->lock);
		prog_cycle(&sd->prog, cmd, 3, seq++);
		pthread_mutex_unlock(&sd->lock);
	}
	CHECK_EQ(atomic_load(&sd->prog.result), PR_DONE);
	CHECK_EQ(sd->prog.play.cur.pos[0], 0);
	if (atomic_load(&sd->prog.result) != PR_DONE)
		printf("  run: result %d, error %s\n", atomic_load(&sd->prog.result), sd->prog.info.error);
	end_feeder(sd);
	unlink(path);
	free(sd);
}

int main(void)
{
	test_session();
	test_sine_then_hold();
	test_idle_hold();
	test_path_error();
	test_requests();
	test_feedback_axis_count();
	test_peer_error();
	test_param_answers_checked();
	test_param_save_failure();
	test_cycle_bounds();
	test_control_peer();
	test_control_trickle();
	test_run_fifo_refused();
	test_run_dry_run_bounded();
	test_run_checked_text_runs();
	return check_summary("servod unit");
}
