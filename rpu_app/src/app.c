/* SPDX-License-Identifier: MIT */
/*
 * app.c - the servo application: N simulated axes (N = parameter "axes",
 * at most AMP_MAX_AXES), each a plant model (motor + load inertia, viscous
 * friction, torque constant, current limit) under a cascaded controller
 * (P position loop with velocity feed-forward and velocity limit, PI
 * velocity loop with anti-windup and current limit), closed on the FINE
 * interpolation of Linux's coarse setpoints (coarse/fine interpolation split): each cycle's new
 * coarse target is reached in SP fine_steps (4) linear sub-steps of T/4,
 * and the loops and plants run once per sub-step.
 *
 * Safe stop (Linux stalled or gone): the velocity reference ramps from the
 * axis' current speed to zero at decel_max, the position reference follows
 * it, then the axis holds that position; status bits SP_AX_SAFESTOP and
 * SP_AX_STANDSTILL report it. Left only by SP_CMD_RESUME.
 *
 * Backends (axis.h): each axis is closed either by the internal model
 * below (axis_model_ops) or by a CiA 402 drive on CAN (axis_can_ops,
 * axis_can.c), as the servo devicetree says (BOARD_AXES). This file keeps
 * what every axis shares: parameters, the enable decision, the safe-stop
 * state, the following-error check, the drive bits of the status word.
 *
 * Arithmetic: single-precision float on the VFPv3-D16 (the firmware is
 * built -mfloat-abi=hard; start.S enables the VFP, irq_entry keeps its
 * state across nested handlers); the cost per cycle is measured by link.c
 * (scripts/bench.sh cycle: about 1,600 instructions for 4 axes, was 22,600
 * in soft float).
 */
#include <stdint.h>

#include "board.h"	/* first: amp_lib port */
#include "app.h"
#include "arch.h"
#include "axis.h"
#include "ttc.h"

#define STEPS 4u	/* fine sub-steps per cycle (parameter fine_steps) */
#define TWO_PI 6.28318530718f

static const struct sp_param_desc params[] = SP_PARAM_TABLE_INIT;

static volatile uint32_t pval[SP_P_COUNT];

/* Cached parameters (floats) for the cycle: refreshed by app_param_apply. */
static struct axis_params k;

/* Each axis's backend (app_init, from BOARD_AXES). */
static const struct axis_ops *be[AMP_MAX_AXES];

volatile struct app_debug app_debug;

/* The internal model's state of one axis. */
struct axis {
	float th, w;		/* plant: position rad, speed rad/s */
	float integ;		/* velocity-loop integral, A */
	float cur;		/* last current, A */
	int32_t p0, p1;		/* coarse targets (inc): previous, newest */
	int primed;		/* p0/p1 valid */
	float ss_v, ss_pos;	/* safe stop: ramped speed and position references */
	uint32_t flags;		/* SP_AX_CUR_LIMIT of the last sub-step */
};

static struct axis ax[AMP_MAX_AXES];
static volatile uint32_t safestop, fault, safestops, stop_cycles, resume_req;
static uint32_t ss_cycles;

static float clampf(float v, float lim)
{
	return v > lim ? lim : (v < -lim ? -lim : v);
}

static float absf(float v)
{
	return v < 0.0f ? -v : v;
}

static int32_t to_i32(float v)
{
	if (v > 2147483000.0f)
		return 2147483647;
	if (v < -2147483000.0f)
		return -2147483647;
	return (int32_t)(v + (v >= 0.0f ? 0.5f : -0.5f));
}

static uint32_t default_word(const struct sp_param_desc *d)
{
	switch (d->type) {
	case SP_T_F32: return sp_word_from_f32((float)d->def);
	case SP_T_I32: return (uint32_t)(int32_t)d->def;
	default: return (uint32_t)d->def;
	}
}

static void refresh(void)
{
	uint32_t cpr = pval[SP_P_counts_per_rev];

	k.pos_kp = sp_f32_from_word(pval[SP_P_pos_kp]);
	k.vel_kp = sp_f32_from_word(pval[SP_P_vel_kp]);
	k.vel_ki = sp_f32_from_word(pval[SP_P_vel_ki]);
	k.vel_max = sp_f32_from_word(pval[SP_P_vel_max]);
	k.cur_max = sp_f32_from_word(pval[SP_P_cur_max]);
	k.kt = sp_f32_from_word(pval[SP_P_kt]);
	k.inv_j = 1.0f / sp_f32_from_word(pval[SP_P_inertia]);
	k.friction = sp_f32_from_word(pval[SP_P_friction]);
	k.decel = sp_f32_from_word(pval[SP_P_decel_max]);
	k.fe_max = (int32_t)pval[SP_P_fe_max];
	k.rad_per_inc = TWO_PI / (float)cpr;
	k.inc_per_rad = (float)cpr / TWO_PI;
	k.T = (float)ttc_period_ns() * 1e-9f;
	k.h = k.T / (float)STEPS;
	k.axes = pval[SP_P_axes];
}

static void model_init(uint32_t i)
{
	ax[i] = (struct axis){ 0 };
}

void app_init(void)
{
	for (uint32_t i = 0; i < SP_P_COUNT; i++)
		pval[i] = default_word(&params[i]);
	for (uint32_t i = 0; i < AMP_MAX_AXES; i++) {
		be[i] = &axis_model_ops;
		model_init(i);
	}
#define AXIS_BE(i, backend, bus, node) be[i] = (backend) == AXIS_BACKEND_CAN ? &axis_can_ops : &axis_model_ops;
	BOARD_AXES(AXIS_BE)
#undef AXIS_BE
	safestop = fault = safestops = stop_cycles = resume_req = 0;
	ss_cycles = 0;
	app_debug = (struct app_debug){ 0 };
	refresh();
	for (uint32_t i = 0; i < AMP_MAX_AXES; i++)
		if (be[i] != &axis_model_ops)
			be[i]->init(i);
	if (axis_can_count())
		axis_can_init(&k);
}

const char *app_axis_backend(uint32_t i)
{
	return i < AMP_MAX_AXES && be[i] ? be[i]->name : "none";
}

uint32_t app_param(uint32_t id)
{
	return id < SP_P_COUNT ? pval[id] : 0u;
}

int app_param_check(uint32_t id, uint32_t value)
{
	const struct sp_param_desc *d;

	if (id >= SP_P_COUNT)
		return SP_E_ID;
	d = &params[id];
	if (d->flags & SP_F_RO)
		return value == pval[id] ? SP_OK : SP_E_READONLY;
	switch (d->type) {
	case SP_T_F32: {
		float v = sp_f32_from_word(value);

		if (v != v || v < (float)d->min || v > (float)d->max)
			return SP_E_RANGE;
		break;
	}
	case SP_T_I32:
		if ((int32_t)value < (int32_t)d->min || (int32_t)value > (int32_t)d->max)
			return SP_E_RANGE;
		break;
	default:
		if (value < (uint32_t)d->min || value > (uint32_t)d->max)
			return SP_E_RANGE;
		break;
	}
	if (id == SP_P_cycle_period_us) {
		struct ttc_setting s;

		if (ttc_setting(value, &s))
			return SP_E_RANGE;
	}
	return SP_OK;
}

void app_param_apply(uint32_t id, uint32_t value)
{
	uint32_t flags;

	if (id >= SP_P_COUNT || (params[id].flags & SP_F_RO))
		return;
	if (id == SP_P_cycle_period_us && value != pval[id])
		(void)ttc_cycle_start(value);
	flags = irq_save();	/* the cycle sees all cached values of one set */
	pval[id] = value;
	refresh();
	irq_restore(flags);
}

void app_param_running(uint32_t id, uint32_t value)
{
	uint32_t flags;

	if (id >= SP_P_COUNT)
		return;
	flags = irq_save();
	pval[id] = value;
	refresh();
	irq_restore(flags);
}

void app_safestop(uint32_t reason)
{
	if (safestop)
		return;
	for (uint32_t i = 0; i < AMP_MAX_AXES; i++)
		be[i]->safestop(i, &k);
	fault = reason;
	safestops++;
	ss_cycles = 0;
	stop_cycles = 0;
	safestop = 1;
}

void app_resume(void)
{
	resume_req = 1;
}

int app_resume_allowed(void)
{
	return safestop || (axis_can_count() && axis_can_faulted());
}

int app_in_safestop(void)
{
	return (int)safestop;
}

uint32_t app_fault(void)
{
	return fault;
}

uint32_t app_safestops(void)
{
	return safestops;
}

uint32_t app_stop_cycles(void)
{
	return stop_cycles;
}

/* Velocity loop + plant, one sub-step; returns the current. */
static void loop_step(struct axis *a, float vel_ref)
{
	float e, i_cmd, torque;

	vel_ref = clampf(vel_ref, k.vel_max);
	e = vel_ref - a->w;
	a->integ = clampf(a->integ + k.vel_ki * e * k.h, k.cur_max);
	i_cmd = k.vel_kp * e + a->integ;
	if (absf(i_cmd) > k.cur_max) {
		a->flags |= SP_AX_CUR_LIMIT;
		i_cmd = clampf(i_cmd, k.cur_max);
	}
	a->cur = i_cmd;
	torque = k.kt * i_cmd - k.friction * a->w;
	a->w += torque * k.inv_j * k.h;	/* semi-implicit Euler */
	a->th += a->w * k.h;
}

static void model_safestop(uint32_t i, const struct axis_params *kp)
{
	(void)kp;
	ax[i].ss_v = ax[i].w;
	ax[i].ss_pos = ax[i].th;
}

static void model_resume(uint32_t i)
{
	ax[i].primed = 0;
	ax[i].integ = 0.0f;
}

/* One cycle of the model: STEPS sub-steps of the loops and the plant. */
static void model_cycle(uint32_t i, const struct axis_params *kp, const struct axis_in *in,
			struct amp_fb_axis *fb)
{
	struct axis *a = &ax[i];
	uint32_t st = 0;
	int32_t pos;

	(void)kp;
	a->flags = 0;
	if (in->mode == AXIS_SAFESTOP) {
		float dv = k.decel * k.h;

		for (uint32_t s = 0; s < STEPS; s++) {
			if (a->ss_v > dv)
				a->ss_v -= dv;
			else if (a->ss_v < -dv)
				a->ss_v += dv;
			else
				a->ss_v = 0.0f;
			a->ss_pos += a->ss_v * k.h;
			loop_step(a, a->ss_v + k.pos_kp * (a->ss_pos - a->th));
		}
		a->primed = 0;
		st |= SP_AX_SAFESTOP;
	} else if (in->mode == AXIS_ENABLED) {
		int32_t target = in->hold && !a->primed ? to_i32(a->th * k.inc_per_rad) : in->target;

		if ((in->fresh && !in->hold) || !a->primed) {
			a->p0 = a->primed ? a->p1 : target;
			a->p1 = target;
			a->primed = 1;
		} else {
			a->p0 = a->p1;	/* no new setpoint: hold the last one */
		}
		float d = (float)(a->p1 - a->p0) * k.rad_per_inc;
		float base = (float)a->p0 * k.rad_per_inc;
		float vff = d / k.T;	/* vel_ff of the record is not used */

		for (uint32_t s = 1; s <= STEPS; s++) {
			float ref = base + d * (float)s / (float)STEPS;

			loop_step(a, vff + k.pos_kp * (ref - a->th));
		}
		st |= SP_AX_ENABLED;
	} else {
		/* disabled: no current, the axis coasts on friction */
		a->integ = 0.0f;
		a->primed = 0;
		for (uint32_t s = 0; s < STEPS; s++) {
			a->cur = 0.0f;
			a->w -= k.friction * a->w * k.inv_j * k.h;
			a->th += a->w * k.h;
		}
	}
	pos = to_i32(a->th * k.inc_per_rad);
	if (absf(a->w * k.inc_per_rad * k.T) < 1.0f)
		st |= SP_AX_STANDSTILL;
	fb->status_word = st | a->flags;
	fb->actual_pos = pos;
	fb->actual_vel = to_i32(a->w * k.inc_per_rad);
	fb->current = to_i32(a->cur * 1000.0f);
	fb->following_error = (st & SP_AX_ENABLED) ? a->p1 - pos : 0;
}

static uint32_t model_drive(uint32_t i)
{
	(void)i;
	return SP_AX_MAKE_DRIVE(SP_DRIVE_INTERNAL, 0);
}

const struct axis_ops axis_model_ops = {
	.name = "model",
	.init = model_init,
	.safestop = model_safestop,
	.resume = model_resume,
	.cycle = model_cycle,
	.drive = model_drive,
};

uint32_t app_cycle(const struct amp_cmd_record *cmd, int fresh, struct amp_fb_axis *fb)
{
	uint32_t n = k.axes, still = 0;
	int can = axis_can_count() != 0;

	if (resume_req) {
		resume_req = 0;
		for (uint32_t i = 0; i < AMP_MAX_AXES; i++)
			be[i]->resume(i);
		safestop = 0;
		fault = 0;
	}
	if (n > AMP_MAX_AXES)
		n = AMP_MAX_AXES;
	if (can)
		axis_can_cycle_begin();
	for (uint32_t i = 0; i < n; i++) {
		const struct amp_cmd_axis *c = cmd && i < cmd->n_axes ? &cmd->axis[i] : 0;
		int enabled = c && (c->control_word & AMP_AXIS_ENABLE) &&
			      (cmd->flags & SP_CMDF_MOTION);
		struct axis_in in = { AXIS_DISABLED, fresh, 0, c ? c->target_pos : 0 };

		if (safestop) {
			in.mode = AXIS_SAFESTOP;
		} else if (enabled) {
			in.mode = AXIS_ENABLED;
		} else if (!c && (app_debug.force_enable & (1u << i))) {
			in.mode = AXIS_ENABLED;	/* debug: enabled, holding its position */
			in.hold = 1;
			in.fresh = 0;
		}
		be[i]->cycle(i, &k, &in, &fb[i]);
		if (fb[i].status_word & SP_AX_STANDSTILL)
			still++;
		if ((fb[i].status_word & SP_AX_ENABLED) && (fb[i].following_error > k.fe_max ||
							     fb[i].following_error < -k.fe_max))
			fb[i].status_word |= SP_AX_FE_LIMIT;
		fb[i].status_word |= be[i]->drive(i);
	}
	/* Drives beyond the axes in use (parameter "axes") are held disabled;
	 * the model's are not stepped, as before. */
	for (uint32_t i = n; i < AMP_MAX_AXES; i++) {
		if (be[i] != &axis_model_ops) {
			struct axis_in off = { AXIS_DISABLED, 0, 0, 0 };
			struct amp_fb_axis unused;

			be[i]->cycle(i, &k, &off, &unused);
		}
	}
	if (can)
		axis_can_cycle_end();
	if (safestop) {
		ss_cycles++;
		if (!stop_cycles && still == n)
			stop_cycles = ss_cycles;
	}
	return n;
}
