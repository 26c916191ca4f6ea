/* SPDX-License-Identifier: MIT */
/*
 * axis_can.c - the CAN-drive axis backend (axis.h): each such axis is a
 * CiA 402 drive in cyclic synchronous position mode on one of the
 * firmware's CAN controllers (canps.c), driven by one CANopen master per
 * bus (canopen_master.c). All from the servo devicetree: BOARD_AXES(X)
 * (backend, bus, node id), BOARD_CAN_BUSES(X) (controllers), the bit rate,
 * the interrupt priority and the master's timeouts.
 *
 * One cycle (app_cycle, in the cycle interrupt):
 *   axis_can_cycle_begin  bus-off restart if the interrupt saw one (the
 *                         axes of that bus fault with 0x8140), then every
 *                         frame the interrupt put in the ring goes to the
 *                         bus's master (TPDOs answering the last SYNC,
 *                         heartbeats, EMCY, SDO answers), then its
 *                         supervision (TPDO silence, heartbeat consumer,
 *                         NMT start confirmation: co_master_supervise)
 *   can_cycle (per axis)  the axis's target and enable request for the
 *                         master; its feedback from the last TPDO1
 *   axis_can_cycle_end    each master's cycle: its time stamp when due
 *                         (the global timer in us, canopen_master.h),
 *                         start-up steps, one RPDO per operational
 *                         drive, then the SYNC
 * Nothing here waits for the bus: a full TX FIFO is counted (co_stats).
 *
 * Where the drive state and error code live: struct co_node (state402,
 * phase, fault, error_code, emcy_last) inside each bus's master; the cycle
 * puts them in every feedback record's status word (SP_AX_MAKE_DRIVE,
 * bits 8-11 state, 16-31 error code) through can_drive().
 */
#include <stdint.h>

#include "board.h"
#include "axis.h"
#include "canopen_master.h"
#include "canps.h"
#include "arch.h"
#include "timebase.h"
#include "irq.h"
#include "log.h"

#define STEPS 4u	/* safe-stop ramp sub-steps per cycle, as the model's */
#define CAN_PDO_TIMEOUT_CYCLES 2u	/* consecutive cycles without a drive's TPDO1: axis fault */
#define CAN_FAULT_RESET_MS 100u		/* a drive has this long to leave Fault after the reset */
#define NBUS (BOARD_CAN_COUNT ? BOARD_CAN_COUNT : 1u)

struct can_axis {
	uint8_t used;
	uint8_t bus;
	uint8_t node;
	uint8_t idx;		/* the node's index in its master */
	uint8_t primed;		/* p1 valid */
	uint8_t prev_valid;
	uint8_t ss_active;	/* safe stop ramps the drive (it was enabled) */
	uint8_t last_phase, last_state, last_fault, last_lost;
	uint16_t last_error;
	uint32_t last_st;	/* last cycle's status bits */
	int32_t p1;		/* coarse target */
	int32_t prev_pos;
	int32_t vel;		/* increments / s */
	float ss_v, ss_pos;	/* safe stop ramp, rad/s and rad */
};

struct can_bus {
	uint8_t used;
	uint8_t ok;		/* controller configured */
	uint32_t irq;
	uintptr_t base;
	uint32_t n_nodes;
	uint8_t node_ids[CO_MAX_NODES];
	struct canps dev;
	struct co_master m;
};

static struct can_bus bus[NBUS];
static struct can_axis cax[AMP_MAX_AXES];
static uint32_t n_can;

static int32_t to_i32(float v)
{
	if (v > 2147483000.0f)
		return 2147483647;
	if (v < -2147483000.0f)
		return -2147483647;
	return (int32_t)(v + (v >= 0.0f ? 0.5f : -0.5f));
}

/* a - b without overflow (positions come from the bus: any value). */
static int32_t sat_diff(int32_t a, int32_t b)
{
	int64_t d = (int64_t)a - (int64_t)b;

	if (d > INT32_MAX)
		return INT32_MAX;
	if (d < -INT32_MAX)
		return -INT32_MAX;
	return (int32_t)d;
}

static int send_frame(void *ctx, const struct can_frame *f)
{
	return canps_send(ctx, f) != 0;
}

uint32_t axis_can_count(void)
{
	return (uint32_t)BOARD_CAN_AXES;
}

void axis_can_init(const struct axis_params *k)
{
	static const struct canps_filter filters[4] = {
		{ 0x700u, 0x000u },	/* NMT of another master 0x000, EMCY 0x081..0x0FF */
		{ 0x780u, 0x180u },	/* TPDO1 */
		{ 0x780u, 0x580u },	/* SDO answers */
		{ 0x780u, 0x700u },	/* heartbeat, boot-up */
	};
	struct co_config cfg = {
		.period_us = (uint32_t)(k->T * 1e6f + 0.5f),
		.hb_producer_ms = BOARD_CAN_HEARTBEAT_PRODUCER_MS,
		.hb_consumer_ms = BOARD_CAN_HEARTBEAT_CONSUMER_MS,
		.sdo_timeout_ms = BOARD_CAN_SDO_TIMEOUT_MS,
		.boot_timeout_ms = BOARD_CAN_BOOT_TIMEOUT_MS,
		.boot_retries = 3,
		.sdo_retries = 2,
		.stamp_ms = BOARD_CAN_TIME_STAMP_MS,
		/* the supervision of an operational drive (docs/reliability.md):
		 * NMT start confirmed within the SDO timeout, else sent again
		 * 3 times; 2 cycles without TPDO1 fault the axis; a fault
		 * reset is held up to 100 ms for the drive to leave Fault */
		.start_timeout_ms = BOARD_CAN_SDO_TIMEOUT_MS,
		.start_retries = 3,
		.pdo_timeout_cycles = CAN_PDO_TIMEOUT_CYCLES,
		.fault_reset_ms = CAN_FAULT_RESET_MS,
	};
	struct canps_timing t;

	n_can = 0;
	for (uint32_t b = 0; b < NBUS; b++)
		bus[b] = (struct can_bus){ 0 };
	for (uint32_t i = 0; i < AMP_MAX_AXES; i++)
		cax[i] = (struct can_axis){ 0 };
#define BUS_ROW(b, base_, irq_, lvl) bus[b].base = (base_); bus[b].irq = (irq_);
	BOARD_CAN_BUSES(BUS_ROW)
#undef BUS_ROW
#define AXIS_ROW(i, backend, b, node_)						\
	if ((backend) == AXIS_BACKEND_CAN && (b) < NBUS && bus[b].n_nodes < CO_MAX_NODES) { \
		cax[i].used = 1;						\
		cax[i].bus = (uint8_t)(b);					\
		cax[i].node = (uint8_t)(node_);					\
		cax[i].idx = (uint8_t)bus[b].n_nodes;				\
		cax[i].last_phase = 0xFFu;					\
		bus[b].node_ids[bus[b].n_nodes++] = (uint8_t)(node_);		\
		bus[b].used = 1;						\
		n_can++;							\
	}
	BOARD_AXES(AXIS_ROW)
#undef AXIS_ROW
	if (!n_can)
		return;	/* no axis on a CAN drive (or no CAN controller) */
	if (canps_timing_for(BOARD_CAN_REF_HZ, BOARD_CAN_BITRATE, &t)) {
		log_printf("error: can: %u bit/s not reachable from %u Hz\n", (unsigned)BOARD_CAN_BITRATE,
			   (unsigned)BOARD_CAN_REF_HZ);
		return;
	}
	for (uint32_t b = 0; b < NBUS; b++) {
		struct can_bus *cb = &bus[b];

		if (!cb->used)
			continue;
		if (canps_init(&cb->dev, cb->base, &t, filters, 4)) {
			log_printf("error: can%u: controller at %08x never entered configuration mode\n",
				   (unsigned)b, (unsigned)cb->base);
			continue;
		}
		if (co_master_init(&cb->m, send_frame, &cb->dev, &cfg, cb->node_ids, cb->n_nodes)) {
			log_printf("error: can%u: bad node list\n", (unsigned)b);
			canps_stop(&cb->dev);
			continue;
		}
		if (irq_register(cb->irq, canps_irq, 0, IRQ_TRIGGER_LEVEL, &cb->dev) ||
		    irq_set_priority(cb->irq, BOARD_CAN_PRIORITY) || irq_enable(cb->irq)) {
			log_printf("error: can%u: interrupt %u not registered\n", (unsigned)b, (unsigned)cb->irq);
			canps_stop(&cb->dev);
			continue;
		}
		co_master_start(&cb->m);
		cb->ok = 1;
		log_printf("can%u: controller %08x irq %u prio %02x, %u bit/s (brpr %u btr %03x), %u drive(s), "
			   "heartbeat %u/%u ms\n",
			   (unsigned)b, (unsigned)cb->base, (unsigned)cb->irq, (unsigned)BOARD_CAN_PRIORITY,
			   (unsigned)BOARD_CAN_BITRATE, (unsigned)t.brpr, (unsigned)t.btr, (unsigned)cb->n_nodes,
			   (unsigned)cfg.hb_producer_ms, (unsigned)cfg.hb_consumer_ms);
	}
	for (uint32_t i = 0; i < AMP_MAX_AXES; i++)
		if (cax[i].used)
			log_printf("axis%u: CiA 402 drive, can%u node %u\n", (unsigned)i, (unsigned)cax[i].bus,
				   (unsigned)cax[i].node);
}

void axis_can_cycle_begin(void)
{
	for (uint32_t b = 0; b < NBUS; b++) {
		struct can_bus *cb = &bus[b];
		struct can_frame f;

		if (!cb->ok)
			continue;
		if (canps_service(&cb->dev) == 1) {
			co_master_bus_off(&cb->m);
			log_printf("can%u: bus off: controller restarted (%u so far)\n", (unsigned)b,
				   (unsigned)cb->dev.st.bus_off_recoveries);
		}
		for (uint32_t n = 0; n < CANPS_RX_RING && canps_recv(&cb->dev, &f); n++)
			co_master_rx(&cb->m, &f);
		co_master_supervise(&cb->m);	/* its faults in this cycle's feedback */
	}
}

void axis_can_cycle_end(void)
{
	for (uint32_t b = 0; b < NBUS; b++) {
		if (!bus[b].ok)
			continue;
		if (co_master_stamp_due(&bus[b].m))
			co_master_time_stamp(&bus[b].m, (uint32_t)(timebase_now() / BOARD_TIMEBASE_TICKS_PER_US));
		co_master_cycle(&bus[b].m);
	}
}

void axis_can_stop(void)
{
	for (uint32_t b = 0; b < NBUS; b++)
		if (bus[b].ok)
			canps_stop(&bus[b].dev);
}

static const struct co_node *node_of(uint32_t i)
{
	const struct can_axis *a = &cax[i];

	if (i >= AMP_MAX_AXES || !a->used || !bus[a->bus].ok)
		return 0;
	return co_master_node(&bus[a->bus].m, a->idx);
}

int axis_can_faulted(void)
{
	for (uint32_t i = 0; i < AMP_MAX_AXES; i++) {
		const struct co_node *n = cax[i].used ? node_of(i) : 0;

		if (n && n->fault)
			return 1;
	}
	return 0;
}

static void can_init(uint32_t i)
{
	(void)i;	/* axis_can_init sets up every CAN axis at once */
}

static void can_safestop(uint32_t i, const struct axis_params *k)
{
	struct can_axis *a = &cax[i];
	const struct co_node *n = node_of(i);

	a->ss_active = n && (a->last_st & SP_AX_ENABLED);
	if (!a->ss_active)
		return;
	a->ss_v = (float)a->vel * k->rad_per_inc;
	a->ss_pos = (float)n->target_sent * k->rad_per_inc;	/* what the drive follows */
}

static void can_resume(uint32_t i)
{
	cax[i].primed = 0;
	cax[i].ss_active = 0;
	/* resume acknowledges the drive's fault (a bus off, an EMCY...) */
	if (cax[i].used && cax[i].bus < NBUS)
		co_master_acknowledge(&bus[cax[i].bus].m, cax[i].idx);
}

static void log_changes(uint32_t i, const struct co_node *n)
{
	struct can_axis *a = &cax[i];
	const char *what;

	if (n->phase == a->last_phase && n->state402 == a->last_state && n->fault == a->last_fault &&
	    n->error_code == a->last_error && n->nmt_lost == a->last_lost)
		return;
	if (n->phase == CO_PH_FAILED && a->last_phase != CO_PH_FAILED && n->cfg_reason != CO_CFG_OK)
		log_printf("axis%u: can%u node %u: configuration refused: %04x:%02x = %08x: %s\n", (unsigned)i,
			   (unsigned)a->bus, (unsigned)a->node, (unsigned)n->cfg_index, (unsigned)n->cfg_sub,
			   (unsigned)n->cfg_value, co_cfg_reason_name((enum co_cfg_reason)n->cfg_reason));
	a->last_phase = n->phase;
	a->last_state = n->state402;
	a->last_fault = n->fault;
	a->last_error = n->error_code;
	a->last_lost = n->nmt_lost;
	if (n->phase != CO_PH_OPERATIONAL)
		what = co_phase_name((enum co_node_phase)n->phase);
	else if (n->nmt_lost)
		what = n->nmt_state == 0x04u ? "left operational: nmt stopped" : "left operational: nmt pre-operational";
	else
		what = co_402_name((enum co_402_state)n->state402);
	/* what, then where in time: the master's cycle and the global timer */
	log_printf("axis%u: can%u node %u: %s%s error %04x (cycle %u, t_us %u)\n", (unsigned)i,
		   (unsigned)a->bus, (unsigned)a->node, what, n->fault ? ", fault," : ",", (unsigned)n->error_code,
		   (unsigned)bus[a->bus].m.cycle, (unsigned)(timebase_now() / BOARD_TIMEBASE_TICKS_PER_US));
}

static void can_cycle(uint32_t i, const struct axis_params *k, const struct axis_in *in,
		      struct amp_fb_axis *fb)
{
	struct can_axis *a = &cax[i];
	const struct co_node *n = node_of(i);
	int32_t pos, target;
	uint32_t st = 0;
	int enable = 0;

	if (!n) {	/* the bus never came up */
		*fb = (struct amp_fb_axis){ 0 };
		a->last_st = 0;
		return;
	}
	pos = n->pos_valid ? n->pos_actual : (a->prev_valid ? a->prev_pos : 0);
	target = pos;
	if (in->mode == AXIS_SAFESTOP) {
		if (a->ss_active) {
			float dv = k->decel * k->h;

			for (uint32_t s = 0; s < STEPS; s++) {
				if (a->ss_v > dv)
					a->ss_v -= dv;
				else if (a->ss_v < -dv)
					a->ss_v += dv;
				else
					a->ss_v = 0.0f;
				a->ss_pos += a->ss_v * k->h;
			}
			target = to_i32(a->ss_pos * k->inc_per_rad);
			enable = 1;
		}
		a->primed = 0;
		st |= SP_AX_SAFESTOP;
	} else if (in->mode == AXIS_ENABLED) {
		if (in->hold) {
			if (!a->primed)
				a->p1 = pos;
		} else if (in->fresh || !a->primed) {
			a->p1 = in->target;
		}
		a->primed = 1;
		target = a->p1;
		enable = 1;
	} else {
		a->primed = 0;
	}
	co_master_set(&bus[a->bus].m, a->idx, enable, target);

	if (enable && !n->fault && n->phase == CO_PH_OPERATIONAL && n->state402 == CO402_OPERATION_ENABLED &&
	    in->mode == AXIS_ENABLED)
		st |= SP_AX_ENABLED;
	if (a->prev_valid) {
		a->vel = to_i32((float)sat_diff(pos, a->prev_pos) / k->T);
		if (pos == a->prev_pos)
			st |= SP_AX_STANDSTILL;
	} else {
		a->vel = 0;
		st |= SP_AX_STANDSTILL;
	}
	a->prev_pos = pos;
	a->prev_valid = n->pos_valid;
	a->last_st = st;
	fb->status_word = st;
	fb->actual_pos = pos;
	fb->actual_vel = a->vel;
	fb->current = 0;	/* not mapped in TPDO1 */
	fb->following_error = (st & SP_AX_ENABLED) ? sat_diff(a->p1, pos) : 0;
	log_changes(i, n);
}

/* The NMT state as the status word carries it (SP_NMT_*). */
static uint32_t nmt_bits(const struct co_node *n)
{
	switch (n->nmt_state) {
	case 0x00u: return SP_AX_MAKE_NMT(SP_NMT_BOOTUP);
	case 0x04u: return SP_AX_MAKE_NMT(SP_NMT_STOPPED);
	case 0x05u: return SP_AX_MAKE_NMT(SP_NMT_OPERATIONAL);
	case 0x7Fu: return SP_AX_MAKE_NMT(SP_NMT_PRE_OPERATIONAL);
	default: return SP_AX_MAKE_NMT(SP_NMT_NONE);
	}
}

/* An operational node that does not follow its PDOs: silent (heartbeat
 * lost), out of NMT Operational, or without TPDO1 (now, or latched until
 * the acknowledgement, so that Linux sees it for a cycle at least and a
 * running program ends on it). */
static int not_following(const struct co_node *n)
{
	if (n->fault && n->error_code == CO_ERR_HEARTBEAT && !n->hb_armed)
		return 1;
	if (n->nmt_lost || n->pdo_silent >= CAN_PDO_TIMEOUT_CYCLES)
		return 1;
	return n->fault && n->error_code == CO_ERR_PDO_TIMEOUT;
}

static uint32_t can_drive(uint32_t i)
{
	const struct co_node *n = node_of(i);
	uint32_t state;

	if (!n)
		return SP_AX_MAKE_DRIVE(SP_DRIVE_OFFLINE, 0);
	switch (n->phase) {
	case CO_PH_CONFIG:
	case CO_PH_START:
		state = SP_DRIVE_CONFIGURING;
		break;
	case CO_PH_OPERATIONAL:
		if (not_following(n)) {
			state = SP_DRIVE_OFFLINE;
			break;
		}
		switch (n->state402) {
		case CO402_NOT_READY: state = SP_DRIVE_NOT_READY; break;
		case CO402_SWITCH_ON_DISABLED: state = SP_DRIVE_SWITCH_ON_DISABLED; break;
		case CO402_READY_TO_SWITCH_ON: state = SP_DRIVE_READY; break;
		case CO402_SWITCHED_ON: state = SP_DRIVE_SWITCHED_ON; break;
		case CO402_OPERATION_ENABLED: state = SP_DRIVE_OPERATION_ENABLED; break;
		case CO402_QUICK_STOP_ACTIVE: state = SP_DRIVE_QUICK_STOP; break;
		case CO402_FAULT_REACTION_ACTIVE: state = SP_DRIVE_FAULT_REACTION; break;
		case CO402_FAULT: state = SP_DRIVE_FAULT; break;
		default: state = SP_DRIVE_CONFIGURING; break;	/* no TPDO yet */
		}
		break;
	default:	/* not started, waiting for boot-up, failed */
		state = SP_DRIVE_OFFLINE;
		break;
	}
	return SP_AX_MAKE_DRIVE(state, n->fault ? n->error_code : 0u) | nmt_bits(n);
}

const struct axis_ops axis_can_ops = {
	.name = "can",
	.init = can_init,
	.safestop = can_safestop,
	.resume = can_resume,
	.cycle = can_cycle,
	.drive = can_drive,
};

int axis_can_get_stats(uint32_t b, struct axis_can_stats *out)
{
	uint32_t flags;

	if (b >= NBUS || !bus[b].ok)
		return -1;
	flags = irq_save();
	co_master_stats(&bus[b].m, &out->co);
	canps_get_stats(&bus[b].dev, &out->can);
	irq_restore(flags);
	return 0;
}

void axis_can_log_stats(void)
{
	struct axis_can_stats s;

	for (uint32_t b = 0; b < NBUS; b++) {
		if (axis_can_get_stats(b, &s))
			continue;
		log_printf("stats can=%u nodes_op=%u sync=%u sync_missed=%u rpdo=%u rpdo_missed=%u tpdo=%u "
			   "pdo_missing=%u pdo_missing_max=%u emcy=%u hb_timeouts=%u faults=%u sdo_ok=%u "
			   "sdo_fail=%u rx_bad=%u pdo_timeouts=%u nmt_left=%u start_retries=%u fault_resets=%u "
			   "reset_refused=%u\n",
			   (unsigned)b, (unsigned)s.co.nodes_operational, (unsigned)s.co.sync_sent,
			   (unsigned)s.co.sync_missed, (unsigned)s.co.rpdo_sent, (unsigned)s.co.rpdo_missed,
			   (unsigned)s.co.tpdo_rx, (unsigned)s.co.pdo_missing, (unsigned)s.co.pdo_missing_max,
			   (unsigned)s.co.emcy, (unsigned)s.co.hb_timeouts, (unsigned)s.co.faults,
			   (unsigned)s.co.sdo_ok, (unsigned)(s.co.sdo_abort + s.co.sdo_timeout + s.co.sdo_bad),
			   (unsigned)s.co.rx_bad, (unsigned)s.co.pdo_timeouts, (unsigned)s.co.nmt_left,
			   (unsigned)s.co.start_retries, (unsigned)s.co.fault_resets,
			   (unsigned)s.co.fault_reset_refused);
		log_printf("stats canps=%u tx=%u tx_busy=%u rx=%u rx_dropped=%u rx_fifo_overflow=%u ring_max=%u "
			   "irqs=%u errors=%u tec=%u rec=%u error_passive=%u bus_off=%u recoveries=%u\n",
			   (unsigned)b, (unsigned)s.can.tx_frames, (unsigned)s.can.tx_busy,
			   (unsigned)s.can.rx_frames, (unsigned)s.can.rx_dropped,
			   (unsigned)s.can.rx_fifo_overflow, (unsigned)s.can.ring_max, (unsigned)s.can.irqs,
			   (unsigned)s.can.error_irqs, (unsigned)s.can.tec, (unsigned)s.can.rec,
			   (unsigned)s.can.error_passive, (unsigned)s.can.bus_off,
			   (unsigned)s.can.bus_off_recoveries);
	}
}
