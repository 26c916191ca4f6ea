/* SPDX-License-Identifier: MIT */
/*
 * servo_proto.h - THE application protocol between servod (Linux, CPU0)
 * and the servo firmware rpu_app (CPU1), on top of amp_lib:
 *
 *  - mailbox (non-periodic) command codes, payloads and error statuses of
 *    the parameter service, the status query and the debug commands;
 *  - the parameter table: id, name, type, unit, range, default, flags;
 *  - the meaning of the periodic records' words (command flags, axis
 *    status bits) and of the servo line's fault codes.
 *
 * Included by rpu_app/src/app.c and linux/servod/ (servod, ampctl); documented in
 * docs/cycle.md. Freestanding C11: no libc needed (the firmware has none).
 * All payload words are little-endian 32-bit; floats are IEEE-754 binary32
 * carried bit for bit in a 32-bit word.
 */
#ifndef SERVOAMP_SERVO_PROTO_H
#define SERVOAMP_SERVO_PROTO_H

#include <stdint.h>

#include "amp/amp_config.h"	/* AMP_MAX_AXES */

#define SP_VERSION 1u

/* ---- mailbox commands (struct amp_msg.command) -------------------------
 * Request / response payloads are arrays of 32-bit words.              */
enum sp_command {
	/* req {id}                      resp {id, value}                     */
	SP_CMD_PARAM_GET = 0x0101u,
	/* req {id, value}               resp {id, value as applied}          */
	SP_CMD_PARAM_SET = 0x0102u,
	/* req {n, (id, value) x n}      resp {n}; all checked before any is
	 * applied: one bad entry rejects the whole request (no change)     */
	SP_CMD_PARAM_SET_MANY = 0x0103u,
	/* req {}                        resp struct sp_status                */
	SP_CMD_STATUS = 0x0201u,
	/* req {}  leave SAFESTOP (Linux is back): axes follow commands again */
	SP_CMD_RESUME = 0x0202u,
	/* req {what}  debug: SP_DEBUG_*; resp {} (sent before it takes effect) */
	SP_CMD_DEBUG = 0x0f01u,
};

/* Debug commands (tests): make the firmware fail on purpose. */
enum sp_debug {
	/* The cycle handler still acknowledges its interrupt but does no
	 * exchange and no heartbeat (a servo loop stuck in its cycle). The
	 * background loop still polls the STOP word, so remoteproc can stop
	 * it even in QEMU (whose SLCR cannot reset CPU1). */
	SP_DEBUG_HANG = 1u,
	/* Undefined instruction in the background loop: the fault handler
	 * logs, writes 'CRSH' and waits for STOP. */
	SP_DEBUG_CRASH = 2u,
	/* The servo line says FAULT (fault SP_FAULT_DEBUG), then the cycle
	 * hangs as with SP_DEBUG_HANG (a firmware that faults and stops). */
	SP_DEBUG_FAULT = 3u,
	/* The next PARAM_GET or PARAM_SET answer carries 0xffffffff as its
	 * value (outside every parameter's range; NaN for the floats); the
	 * request itself is served as usual. */
	SP_DEBUG_BADPARAM = 4u,
	/* The next cycle handler (an interrupt, on the SVC stack like every
	 * nested handler) recurses until the SVC stack overflows into its
	 * guard page: a data abort, reported by the fault handler as
	 * "SVC stack overflow" with CRSH, then as SP_DEBUG_CRASH. Refused
	 * (SP_E_STATE) by a firmware built without the MMU (no guard). */
	SP_DEBUG_STACK = 5u,
	/* req {6, us}: every cycle handler busy-waits us microseconds more
	 * (0..10000, 0 = off) in its control step, inside its measured cost
	 * (a slow control law; only while attached to Linux). */
	SP_DEBUG_SLOW = 6u,
	/* Every cycle handler ends with its own interrupt pending again (set
	 * at the GIC), as if its cost exceeded the period: handlers run back
	 * to back and the background loop never runs again. */
	SP_DEBUG_OVERLOAD = 7u,
	/* An interrupt the firmware has no handler for starts firing: the
	 * TTC counter used by neither cycle, in interval mode, its level
	 * interrupt enabled, targeted at this core and never cleared (a level
	 * storm from a misrouted or misconfigured source). */
	SP_DEBUG_STRAY_IRQ = 8u,
	/* The next cycle interrupt takes a data abort (the SVC stack's guard
	 * page) right after the firmware acknowledged it at the GIC, before
	 * its latency probe: CRSH as SP_DEBUG_CRASH, with the interrupt
	 * active. A stop and a new start must find the CPU interface idle and
	 * the cycle running. Refused (SP_E_STATE) without the MMU. */
	SP_DEBUG_IRQ_ABORT = 9u,
};

/* Application error statuses (struct amp_msg.status), beside amp_lib's
 * AMP_E_* (-1..-9) which the transport itself may return. */
enum sp_error {
	SP_OK = 0,
	SP_E_CMD = -100,	/* unknown command */
	SP_E_LENGTH = -101,	/* payload length wrong for the command */
	SP_E_ID = -102,		/* unknown parameter id */
	SP_E_RANGE = -103,	/* value outside [min, max] (or NaN) */
	SP_E_READONLY = -104,	/* parameter cannot be written */
	SP_E_STATE = -105,	/* not possible in the current state */
	SP_E_OVERLOAD = -106,	/* cycle_period_us shorter than the measured worst
				 * handler cost allows (sp_period_fits); nothing applied */
};

/* ---- parameters ---------------------------------------------------------- */
enum sp_type { SP_T_U32 = 0, SP_T_I32 = 1, SP_T_F32 = 2 };

/* An SP_T_F32 value and the payload word that carries it, bit for bit
 * (IEEE-754 binary32; a union, as the firmware has no memcpy of its own). */
static inline float sp_f32_from_word(uint32_t w)
{
	union { uint32_t u; float f; } c = { .u = w };
	return c.f;
}

static inline uint32_t sp_word_from_f32(float f)
{
	union { uint32_t u; float f; } c = { .f = f };
	return c.u;
}

#define SP_F_RO      (1u << 0)	/* read-only */
#define SP_F_RESTORE (1u << 1)	/* servod keeps it in its file and loads it at every attach */

/* The one parameter table: X(id, name, type, unit, min, max, default, flags).
 * min/max/default are written as numbers of the parameter's type. */
#define SP_PARAMS(X) \
	X(0,  axes,            SP_T_U32, "",          1,      AMP_MAX_AXES, 4,      SP_F_RESTORE) \
	X(1,  cycle_period_us, SP_T_U32, "us",        125,    10000,   1000,   SP_F_RESTORE) \
	X(2,  wd_limit,        SP_T_U32, "cycles",    2,      1000,    10,     SP_F_RESTORE) \
	X(3,  pos_kp,          SP_T_F32, "1/s",       0,      2000,    60,     SP_F_RESTORE) \
	X(4,  vel_kp,          SP_T_F32, "A.s/rad",   0,      100,     0.5,    SP_F_RESTORE) \
	X(5,  vel_ki,          SP_T_F32, "A/rad",     0,      100000,  20,     SP_F_RESTORE) \
	X(6,  vel_max,         SP_T_F32, "rad/s",     0.1,    2000,    300,    SP_F_RESTORE) \
	X(7,  cur_max,         SP_T_F32, "A",         0.1,    100,     10,     SP_F_RESTORE) \
	X(8,  kt,              SP_T_F32, "N.m/A",     0.001,  10,      0.1,    SP_F_RESTORE) \
	X(9,  inertia,         SP_T_F32, "kg.m2",     1e-6,   1,       1e-4,   SP_F_RESTORE) \
	X(10, friction,        SP_T_F32, "N.m.s/rad", 0,      1,       1e-4,   SP_F_RESTORE) \
	X(11, counts_per_rev,  SP_T_U32, "inc",       100,    1000000, 10000,  SP_F_RESTORE) \
	X(12, decel_max,       SP_T_F32, "rad/s2",    1,      1000000, 2000,   SP_F_RESTORE) \
	X(13, fe_max,          SP_T_I32, "inc",       1,      100000000, 100000, SP_F_RESTORE) \
	X(14, fine_steps,      SP_T_U32, "",          4,      4,       4,      SP_F_RO)

enum sp_param_id {
#define SP_X_ENUM(id, name, type, unit, min, max, def, flags) SP_P_##name = id,
	SP_PARAMS(SP_X_ENUM)
#undef SP_X_ENUM
	SP_P_COUNT
};

struct sp_param_desc {
	uint32_t id;
	const char *name;
	uint32_t type;		/* enum sp_type */
	const char *unit;
	double min, max, def;	/* in the parameter's type (exact for u32/i32) */
	uint32_t flags;
};

/* Only for code that can use double constants (both sides can: the
 * firmware converts them with its VFP at init). */
#define SP_X_DESC(id, name, type, unit, min, max, def, flags) \
	{ id, #name, type, unit, (double)(min), (double)(max), (double)(def), flags },
#define SP_PARAM_TABLE_INIT { SP_PARAMS(SP_X_DESC) }

/*
 * The firmware accepts a new cycle_period_us only if its worst cycle
 * handler cost measured so far (struct sp_status cycle_ticks_max, handler
 * entry to feedback published, global-timer ticks of 10 ns), with a margin
 * of one quarter, fits in the period: the rest is left to the background
 * loop (mailbox, log, STOP) and to the entry latency. The value in force is
 * always accepted again (parameter restore).
 */
#define SP_PERIOD_MARGIN_NUM 5u	/* worst cost x 5/4 <= period */
#define SP_PERIOD_MARGIN_DEN 4u
static inline int sp_period_fits(uint32_t period_us, uint32_t worst_ns)
{
	return (uint64_t)worst_ns * SP_PERIOD_MARGIN_NUM <= (uint64_t)period_us * 1000u * SP_PERIOD_MARGIN_DEN;
}

/* Largest request: SET_MANY with every parameter. */
#define SP_SET_MANY_MAX SP_P_COUNT

/* ---- SP_CMD_STATUS response ------------------------------------------------ */
struct sp_status {
	uint32_t version;	/* SP_VERSION */
	uint32_t state;		/* servo line state (AMP_SSTATE_*) */
	uint32_t fault;		/* SP_FAULT_* or AMP_E_* */
	uint32_t cycles;	/* cycle interrupts handled since start */
	uint32_t missed;	/* interval events lost (timer gaps > 1.5 periods) */
	uint32_t overruns;	/* periods longer than 1.5 x nominal */
	uint32_t rx_fresh, rx_stale, rx_torn, rx_missed, rx_invalid;
	uint32_t attach_count;
	uint32_t period_us;
	uint32_t axes;
	uint32_t safestops;	/* entries into SAFESTOP since start */
	uint32_t stop_cycles;	/* cycles from the watchdog to standstill (last safe stop) */
	uint32_t irq_lat_max_ns;	/* cycle interrupt entry latency, max */
	/* Costs in A9 global-timer ticks (10 ns), measured in the cycle handler:
	 * rx = handler entry -> commands consumed (amp_servo_cycle_rx done),
	 * ctrl = interpolation + loops + plant models, tx = feedback published,
	 * cycle = whole handler work; means over `samples` cycles. */
	uint32_t samples;
	uint32_t rx_ticks_max, rx_ticks_mean;
	uint32_t ctrl_ticks_max, ctrl_ticks_mean;
	uint32_t tx_ticks_max, tx_ticks_mean;
	uint32_t cycle_ticks_max, cycle_ticks_mean;
	uint32_t mbox_served;
	uint32_t linux_cycle;	/* Linux cycle number in the last commands consumed */
	uint32_t hb_linux_cycles;	/* cycles since Linux's heartbeat last moved */
	/* SVC stack (main loop and every interrupt handler, nested): deepest
	 * use since start (high-water mark of the painted stack) and size, in
	 * bytes. An overflow faults on the guard page below it. */
	uint32_t svc_stack_used;
	uint32_t svc_stack_size;
	/* Interrupts taken without a handler, how many of them were disabled
	 * at the GIC distributor, and the ID of the last one disabled. */
	uint32_t irq_unhandled;
	uint32_t irq_disabled;
	uint32_t irq_disabled_last;
	uint32_t period_refused;	/* cycle_period_us values refused (SP_E_OVERLOAD) */
	/* The firmware's GIC CPU interface at its start: interrupts an earlier
	 * run left active there and this start completed, and the running
	 * priority left after that: 0xff (idle) or, if the interface stays
	 * busy, no interrupt at or below that priority is ever taken (the
	 * trace says which; only a reset of the GIC clears it). */
	uint32_t irq_drained;
	uint32_t irq_busy_prio;
};

/* ---- periodic records ----------------------------------------------------- */
/* amp_cmd_record.flags */
#define SP_CMDF_MOTION (1u << 0)	/* targets are valid (servod is running motion) */

/* amp_fb_axis.status_word bits */
#define SP_AX_ENABLED    (1u << 0)
#define SP_AX_SAFESTOP   (1u << 1)	/* axis ramped down / held because of a safe stop */
#define SP_AX_STANDSTILL (1u << 2)	/* |velocity| below 1 inc per cycle */
#define SP_AX_CUR_LIMIT  (1u << 3)	/* current limited in this cycle */
#define SP_AX_FE_LIMIT   (1u << 4)	/* following error over fe_max */
/*
 * Bits 8-11: the axis's drive (issue 22). 0: the firmware's internal motor
 * model; otherwise a CANopen CiA 402 drive and its state as the master last
 * saw it (SP_DRIVE_*). Bits 16-31: the drive's last error code (EMCY, CiA
 * 301/402: 0x8611 following error, 0x2310 over-current, ...), 0 if none,
 * 0x8130 when its heartbeat went silent, the master's own 0xFFxx codes
 * (rpu_app/src/canopen_master.h CO_ERR_*). Bits 12-14: the drive's NMT
 * state as the master last saw it (SP_NMT_*, 0 for the internal model or
 * before any). Existing readers that test bits 0-4 are unaffected.
 */
#define SP_AX_DRIVE_SHIFT 8
#define SP_AX_DRIVE_MASK  (0xfu << SP_AX_DRIVE_SHIFT)
#define SP_AX_ERROR_SHIFT 16
#define SP_AX_ERROR_MASK  (0xffffu << SP_AX_ERROR_SHIFT)
#define SP_AX_DRIVE(sw)   (((sw) & SP_AX_DRIVE_MASK) >> SP_AX_DRIVE_SHIFT)
#define SP_AX_ERROR(sw)   (((sw) & SP_AX_ERROR_MASK) >> SP_AX_ERROR_SHIFT)
#define SP_AX_MAKE_DRIVE(state, error) \
	((((uint32_t)(state) << SP_AX_DRIVE_SHIFT) & SP_AX_DRIVE_MASK) | \
	 (((uint32_t)(error) << SP_AX_ERROR_SHIFT) & SP_AX_ERROR_MASK))

/* SP_AX_DRIVE() values */
#define SP_DRIVE_INTERNAL          0u	/* the firmware's own motor model */
#define SP_DRIVE_OFFLINE           1u	/* not following the PDOs: no boot-up, heartbeat lost, TPDO silent, left NMT Operational */
#define SP_DRIVE_CONFIGURING       2u	/* NMT/SDO configuration by the master */
#define SP_DRIVE_NOT_READY         3u	/* CiA 402 "Not ready to switch on" */
#define SP_DRIVE_SWITCH_ON_DISABLED 4u
#define SP_DRIVE_READY             5u	/* "Ready to switch on" */
#define SP_DRIVE_SWITCHED_ON       6u
#define SP_DRIVE_OPERATION_ENABLED 7u
#define SP_DRIVE_QUICK_STOP        8u	/* "Quick stop active" */
#define SP_DRIVE_FAULT_REACTION    9u	/* "Fault reaction active" */
#define SP_DRIVE_FAULT             10u
#define SP_DRIVE_STATES            11u

#define SP_AX_NMT_SHIFT 12
#define SP_AX_NMT_MASK  (0x7u << SP_AX_NMT_SHIFT)
#define SP_AX_NMT(sw)   (((sw) & SP_AX_NMT_MASK) >> SP_AX_NMT_SHIFT)
#define SP_AX_MAKE_NMT(nmt) (((uint32_t)(nmt) << SP_AX_NMT_SHIFT) & SP_AX_NMT_MASK)
/* SP_AX_NMT() values (CiA 301 NMT states) */
#define SP_NMT_NONE            0u	/* internal model, or no heartbeat / NMT seen */
#define SP_NMT_BOOTUP          1u
#define SP_NMT_STOPPED         2u
#define SP_NMT_OPERATIONAL     3u
#define SP_NMT_PRE_OPERATIONAL 4u
#define SP_NMT_STATES          5u

/* servo line fault word while SAFESTOP (amp_servo_set_state) */
#define SP_FAULT_NONE        0u
#define SP_FAULT_LINUX_STALL 0x57440001u	/* "WD" + 1: Linux heartbeat still for wd_limit cycles */
#define SP_FAULT_LINUX_GONE  0x57440002u	/* Linux closed / re-initialised the region */
#define SP_FAULT_FOLLOWING   0x57440003u	/* following error over fe_max */
#define SP_FAULT_DEBUG       0x57440004u	/* state FAULT written on request (SP_DEBUG_FAULT) */

#endif /* SERVOAMP_SERVO_PROTO_H */
