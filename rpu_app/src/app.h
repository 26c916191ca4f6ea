/* SPDX-License-Identifier: MIT */
#ifndef RPU_APP_H
#define RPU_APP_H

#include <stdint.h>

#include "amp/amp.h"
#include "servoamp/servo_proto.h"

/*
 * The servo application (app.c): parameter table, fine interpolation,
 * position/velocity loops and plant models of N simulated axes, safe stop.
 * Transport-free: link.c calls it from the cycle interrupt (app_cycle) and
 * from the background loop (app_mbox).
 */
void app_init(void);

/*
 * One cycle. cmd: the commands held (NULL: no Linux session, axes
 * disabled); fresh: cmd carries a new coarse setpoint. Writes n_axes
 * feedback entries to fb and returns n_axes.
 */
uint32_t app_cycle(const struct amp_cmd_record *cmd, int fresh, struct amp_fb_axis *fb);

/* Enter safe stop (idempotent; the first reason is kept). */
void app_safestop(uint32_t reason);
/* Leave safe stop (SP_CMD_RESUME). */
void app_resume(void);
int app_in_safestop(void);
/* SP_CMD_RESUME is taken in safe stop, or while a drive's fault is
 * latched (the resume acknowledges it: axis_ops.resume). */
int app_resume_allowed(void);
uint32_t app_fault(void);
uint32_t app_safestops(void);
uint32_t app_stop_cycles(void);

/* The backend name of axis i ("model", "can"; axis.h). */
const char *app_axis_backend(uint32_t i);

/* Debug (the QEMU tests without Linux write it through the gdbstub by
 * symbol; cleared by app_init): axes whose bit is set run enabled, holding
 * their position, while no Linux command is held. */
struct app_debug {
	uint32_t force_enable;
};
extern volatile struct app_debug app_debug;

/* Parameter access (values as 32-bit words). */
uint32_t app_param(uint32_t id);
int app_param_check(uint32_t id, uint32_t value);	/* SP_OK or SP_E_* */
void app_param_apply(uint32_t id, uint32_t value);	/* background loop only */
/* At start: the value already in force (cycle_period_us: the period the
 * cycle timer runs at), taken without applying it. */
void app_param_running(uint32_t id, uint32_t value);

#endif
