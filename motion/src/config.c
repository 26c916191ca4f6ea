/* SPDX-License-Identifier: MIT */
/* The configuration: defaults and range checks (see motion.h). */
#include "config.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

void motion_config_default(struct motion_config *c)
{
	memset(c, 0, sizeof(*c));
	c->n_axes = 3;
	c->period_us = 1000;
	c->increments_per_mm = 1000.0;
	for (int k = 0; k < MOTION_MAX_AXES; k++) {
		c->axis[k].vmax = 200.0;
		c->axis[k].amax = 2000.0;
		c->axis[k].jmax = 200000.0;
		c->axis[k].min = -1000.0;
		c->axis[k].max = 1000.0;
	}
	c->chord_tol = 0.001;
	c->junction_share = 0.5;
	c->lookahead = 32;
	c->stream_size = 16384;
	c->stream_high = 12288;
	c->stream_low = 4096;
	c->q_blocks = 64;
	c->q_segments = 256;
	c->q_planned = 64;
	c->q_profiles = 64;
	c->q_setpoints = 64;
	c->batch = 8;
	c->policy = MOTION_POLICY_HYBRID;
	c->interp_lanes = MOTION_DEFAULT_LANES;
	c->interp_chunk = 0;
	c->trace_samples = 0;
	c->monitor_period_us = 10000;
}

static int cfg_fail(struct motion_error *err, const char *msg, int k)
{
	if (err) {
		memset(err, 0, sizeof(*err));
		err->code = MOTION_E_CONFIG;
		if (k >= 0)
			snprintf(err->msg, sizeof(err->msg), "axis %d: %s", k, msg);
		else
			snprintf(err->msg, sizeof(err->msg), "%s", msg);
	}
	return -1;
}

int config_check(const struct motion_config *c, struct motion_error *err)
{
	const double lim = 2147483647.0;

	if (c->n_axes < 1 || c->n_axes > MOTION_MAX_AXES)
		return cfg_fail(err, "n_axes must be 1..6", -1);
	if (c->period_us < 50 || c->period_us > 100000)
		return cfg_fail(err, "period_us must be 50..100000", -1);
	if (!(c->increments_per_mm > 0) || !isfinite(c->increments_per_mm))
		return cfg_fail(err, "increments_per_mm must be > 0", -1);
	for (uint32_t k = 0; k < c->n_axes; k++) {
		const struct motion_axis_limits *a = &c->axis[k];
		if (!(a->vmax > 0) || !(a->amax > 0) || !isfinite(a->vmax) ||
		    !isfinite(a->amax))
			return cfg_fail(err, "vmax and amax must be > 0", (int)k);
		if (c->jerk_limited && (!(a->jmax > 0) || !isfinite(a->jmax)))
			return cfg_fail(err, "jmax must be > 0", (int)k);
		if (!(a->min < a->max))
			return cfg_fail(err, "travel min must be below max", (int)k);
		if (fabs(a->min) * c->increments_per_mm >= lim ||
		    fabs(a->max) * c->increments_per_mm >= lim)
			return cfg_fail(err, "travel does not fit int32 increments", (int)k);
		if (a->vmax * c->increments_per_mm >= lim)
			return cfg_fail(err, "vmax does not fit int32 increments/s", (int)k);
		if (c->start_pos[k] < a->min || c->start_pos[k] > a->max)
			return cfg_fail(err, "start position outside the travel", (int)k);
	}
	if (!(c->chord_tol > 0))
		return cfg_fail(err, "chord_tol must be > 0", -1);
	if (!(c->junction_share > 0 && c->junction_share < 1))
		return cfg_fail(err, "junction_share must be in (0, 1)", -1);
	if (c->lookahead < 2 || c->lookahead > 4096)
		return cfg_fail(err, "lookahead must be 2..4096", -1);
	if (c->stream_size < 2u * (MOTION_MAX_LINE + 1u) || c->stream_size > (1u << 28))
		return cfg_fail(err, "stream_size must be >= 514 bytes", -1);
	if (!(c->stream_low < c->stream_high && c->stream_high <= c->stream_size))
		return cfg_fail(err, "need stream_low < stream_high <= stream_size", -1);
	if (c->q_blocks < 2 || c->q_segments < 2 || c->q_planned < 2 ||
	    c->q_profiles < 2 || c->q_setpoints < 4)
		return cfg_fail(err, "queue capacities too small", -1);
	if (c->batch < 1 || c->batch > 4096)
		return cfg_fail(err, "batch must be 1..4096", -1);
	if (c->interp_lanes > MOTION_MAX_WORKERS)
		return cfg_fail(err, "interp_lanes must be 0..8", -1);
	if (c->interp_chunk > (1u << 20))
		return cfg_fail(err, "interp_chunk must be 0..1048576", -1);
	if (c->min_job > 4096)
		return cfg_fail(err, "min_job must be 0..4096", -1);
	return 0;
}
