/* SPDX-License-Identifier: MIT */
#ifndef RPU_AXIS_H
#define RPU_AXIS_H

#include <stdint.h>

#include "amp/amp.h"
#include "canopen_master.h"
#include "canps.h"
#include "servoamp/servo_proto.h"

/*
 * The axis-backend interface (issue 22; like servod's setpoint_ops): what
 * closes an axis's loops. app.c keeps what every axis shares (parameters,
 * the enable decision, the safe-stop state, the following-error check) and
 * calls its axis's backend through a small ops table:
 *
 *   AXIS_BACKEND_MODEL  the internal motor-and-load model under the
 *                       firmware's cascaded controller (app.c)
 *   AXIS_BACKEND_CAN    a CiA 402 drive in CSP on a CAN bus, through the
 *                       CANopen master (axis_can.c, canopen_master.c,
 *                       canps.c)
 *
 * Each axis's backend comes from the servo devicetree (servoamp,servo-axis
 * nodes -> BOARD_AXES(X) in board_config.h); axes not described use the
 * model. Every hook runs in the cycle interrupt except init and stop.
 */
enum axis_backend_kind { AXIS_BACKEND_MODEL = 0, AXIS_BACKEND_CAN = 1 };

/* The cached parameters of the cycle (app.c refreshes them). */
struct axis_params {
	uint32_t axes;
	float T, h;		/* cycle and sub-step, s */
	float pos_kp, vel_kp, vel_ki, vel_max, cur_max, kt, inv_j, friction, decel;
	float rad_per_inc, inc_per_rad;
	int32_t fe_max;
};

enum axis_mode { AXIS_DISABLED = 0, AXIS_ENABLED, AXIS_SAFESTOP };

/* One cycle's input of one axis. */
struct axis_in {
	uint32_t mode;		/* enum axis_mode */
	int fresh;		/* ENABLED: target is a new coarse setpoint */
	int hold;		/* ENABLED without a command: hold the position (tests) */
	int32_t target;		/* ENABLED: coarse target, increments */
};

struct axis_ops {
	const char *name;
	/* Start (app_init): the axis's state reset. */
	void (*init)(uint32_t axis);
	/* Safe stop begins: the ramp starts from the axis's speed and position. */
	void (*safestop)(uint32_t axis, const struct axis_params *k);
	/* SP_CMD_RESUME: the axis takes its commands again. */
	void (*resume)(uint32_t axis);
	/*
	 * One cycle: fills fb (status bits SP_AX_ENABLED, SP_AX_SAFESTOP,
	 * SP_AX_STANDSTILL, SP_AX_CUR_LIMIT; positions, velocity, current,
	 * following error). app.c adds SP_AX_FE_LIMIT and the drive bits.
	 */
	void (*cycle)(uint32_t axis, const struct axis_params *k, const struct axis_in *in,
		      struct amp_fb_axis *fb);
	/* The drive bits of the status word: SP_AX_MAKE_DRIVE(state, error). */
	uint32_t (*drive)(uint32_t axis);
};

/* The internal model (app.c). */
extern const struct axis_ops axis_model_ops;
/* A CiA 402 drive on CAN (axis_can.c). */
extern const struct axis_ops axis_can_ops;

/*
 * The CAN side as a whole (axis_can.c): init (controllers, interrupts,
 * masters), the bus work around the axes of one cycle (begin: bus-off
 * restarts, received frames into the masters; end: RPDOs and SYNC), the
 * stop path, and the statistics line.
 */
void axis_can_init(const struct axis_params *k);
void axis_can_cycle_begin(void);
void axis_can_cycle_end(void);
void axis_can_stop(void);
void axis_can_log_stats(void);
uint32_t axis_can_count(void);	/* CAN axes configured */
int axis_can_faulted(void);	/* 1 while a CAN axis' fault is latched */

/* The counters of one bus: its master's and its controller's. */
struct axis_can_stats {
	struct co_stats co;
	struct canps_stats can;
};
/* 0, or -1 for a bus not in use. IRQ-safe snapshot. */
int axis_can_get_stats(uint32_t bus, struct axis_can_stats *out);

#endif
