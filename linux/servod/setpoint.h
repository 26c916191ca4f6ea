/* SPDX-License-Identifier: MIT */
/*
 * setpoint.h - where the cycle's coarse setpoints come from: a source
 * behind a small ops table, chosen every cycle by setpoint_source().
 *
 *   sine     servod's idle motion: a sine per axis (-a amplitude, -f
 *            frequency, phase shifted by pi/4 per axis), until the first
 *            program (unless --idle hold)
 *   program  the G-code runner (program.h): hold, a program's setpoints,
 *            the stop ramp; it takes over from the sine where the sine is
 *            in that cycle
 */
#ifndef SERVOD_SETPOINT_H
#define SERVOD_SETPOINT_H

#include <stdint.h>

#include "amp/amp.h"

struct servod;

struct setpoint_ops {
	const char *name;
	/* cmd[0..n) for the command sequence seq amp_linux_cycle() is about
	 * to publish. Cycle thread, under sd->lock: never blocks. */
	void (*fill)(struct servod *sd, struct amp_cmd_axis *cmd, uint32_t n, uint32_t seq);
	/* After amp_linux_cycle(): rc its result, fresh = a new feedback record (may be NULL). */
	void (*feedback)(struct servod *sd, int rc, const struct amp_fb_record *fb, uint32_t n, int fresh);
};

extern const struct setpoint_ops setpoint_sine, setpoint_program;

/* The source of this cycle. */
const struct setpoint_ops *setpoint_source(struct servod *sd);

#endif
