// SPDX-License-Identifier: MIT
/* setpoint.c - the setpoint sources: the sine, and the program runner's
 * entry points (setpoint.h). */
#define _GNU_SOURCE
#include <math.h>

#include "context.h"

static void sine_fill(struct servod *sd, struct amp_cmd_axis *cmd, uint32_t n, uint32_t seq)
{
	double t = (double)sd->amp.cycle * (double)sd->period_ns * 1e-9;

	(void)seq;
	for (uint32_t i = 0; i < n; i++) {
		cmd[i].control_word = AMP_AXIS_ENABLE;
		cmd[i].target_pos = (int32_t)lround(sd->opt.amplitude *
			sin(2.0 * M_PI * sd->opt.freq * t + (double)i * M_PI / 4.0));
		cmd[i].vel_ff = 0;
		cmd[i].torque_offset = 0;
	}
}

const struct setpoint_ops setpoint_sine = { "sine", sine_fill, 0 };

static void program_fill(struct servod *sd, struct amp_cmd_axis *cmd, uint32_t n, uint32_t seq)
{
	if (prog_on_sine(&sd->prog)) {
		/* the hand-over: the program holds where the sine is now */
		sine_fill(sd, cmd, n, seq);
	} else {
		for (uint32_t i = 0; i < n; i++)
			cmd[i] = (struct amp_cmd_axis){ .control_word = AMP_AXIS_ENABLE };
	}
	prog_cycle(&sd->prog, cmd, n, seq);
}

static void program_feedback(struct servod *sd, int rc, const struct amp_fb_record *fb, uint32_t n, int fresh)
{
	prog_feedback(&sd->prog, rc, fb, n, fresh);
}

const struct setpoint_ops setpoint_program = { "program", program_fill, program_feedback };

const struct setpoint_ops *setpoint_source(struct servod *sd)
{
	return prog_driving(&sd->prog) ? &setpoint_program : &setpoint_sine;
}
