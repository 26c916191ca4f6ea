/* SPDX-License-Identifier: MIT */
/*
 * canopen_master.c - CANopen master for CiA 402 drives in CSP (see
 * canopen_master.h). No transport, no globals, no allocation, no library
 * calls: built into the firmware and, unchanged, into the host unit test.
 */
#include <stddef.h>
#include <stdint.h>

#include "canopen_master.h"

#define COB_NMT 0x000u
#define COB_SYNC 0x080u
#define COB_EMCY 0x080u		/* + node */
#define COB_TPDO1 0x180u	/* + node */
#define COB_RPDO1 0x200u	/* + node */
#define COB_SDO_TX 0x580u	/* server -> client, + node */
#define COB_SDO_RX 0x600u	/* client -> server, + node */
#define COB_HB 0x700u		/* + node */

#define NMT_START 0x01u
#define NMT_RESET_COMM 0x82u

#define NO_NODE 0xFFu
#define CO_ERR_DRIVE_FAULT 0x1000u	/* drive in Fault without an EMCY: generic error */

/* One step of the SDO configuration. */
enum { ST_WRITE, ST_READ };
struct cfg_step {
	uint8_t kind;
	uint8_t sub;
	uint8_t size;		/* write: bytes (1, 2, 4) */
	uint8_t node_rel;	/* value / expected value + node id */
	uint16_t index;
	uint32_t value;		/* write: value; read: expected value under mask */
	uint32_t mask;
};

#define HB_VALUE 0xFFFFFFFFu	/* placeholder: cfg.hb_producer_ms */

static const struct cfg_step steps[] = {
	{ ST_WRITE, 0, 1, 0, 0x6060, 8u, 0 },			/* modes of operation: CSP */
	{ ST_READ, 0, 0, 0, 0x6061, 8u, 0xFFu },		/* modes of operation display */
	{ ST_READ, 0, 0, 0, 0x1A00, 2u, 0xFFu },		/* TPDO1 mapping: 2 entries */
	{ ST_READ, 1, 0, 0, 0x1A00, 0x60410010u, 0xFFFFFFFFu },	/* statusword, 16 bit */
	{ ST_READ, 2, 0, 0, 0x1A00, 0x60640020u, 0xFFFFFFFFu },	/* position actual, 32 bit */
	{ ST_READ, 0, 0, 0, 0x1600, 2u, 0xFFu },		/* RPDO1 mapping: 2 entries */
	{ ST_READ, 1, 0, 0, 0x1600, 0x60400010u, 0xFFFFFFFFu },	/* controlword, 16 bit */
	{ ST_READ, 2, 0, 0, 0x1600, 0x607A0020u, 0xFFFFFFFFu },	/* target position, 32 bit */
	{ ST_READ, 1, 0, 1, 0x1800, COB_TPDO1, 0x800007FFu },	/* TPDO1 COB-ID, valid */
	{ ST_READ, 1, 0, 1, 0x1400, COB_RPDO1, 0x800007FFu },	/* RPDO1 COB-ID, valid */
	{ ST_WRITE, 2, 1, 0, 0x1800, 1u, 0 },			/* TPDO1 on every SYNC */
	{ ST_WRITE, 2, 1, 0, 0x1400, 1u, 0 },			/* RPDO1 applied at SYNC */
	{ ST_WRITE, 0, 2, 0, 0x1017, HB_VALUE, 0 },		/* heartbeat producer time */
};
#define N_STEPS (sizeof(steps) / sizeof(steps[0]))

static uint32_t ms_to_cycles(uint32_t ms, uint32_t period_us)
{
	uint32_t c;

	if (!period_us)
		period_us = 1000u;
	c = (uint32_t)(((uint64_t)ms * 1000u + period_us - 1u) / period_us);
	return c ? c : 1u;
}

static uint32_t rd_le(const uint8_t *p, uint32_t n)
{
	uint32_t v = 0;

	for (uint32_t i = 0; i < n && i < 4u; i++)
		v |= (uint32_t)p[i] << (8u * i);
	return v;
}

static void wr_le(uint8_t *p, uint32_t v, uint32_t n)
{
	for (uint32_t i = 0; i < n && i < 4u; i++)
		p[i] = (uint8_t)(v >> (8u * i));
}

static void frame_clear(struct can_frame *f)
{
	f->id = 0;
	f->dlc = 0;
	f->rtr = 0;
	for (uint32_t i = 0; i < 8u; i++)
		f->data[i] = 0;
}

static int tx(struct co_master *m, const struct can_frame *f)
{
	if (m->send(m->ctx, f)) {
		m->st.tx_busy++;
		return -1;
	}
	return 0;
}

static int expired(const struct co_master *m, uint32_t deadline)
{
	return (int32_t)(m->cycle - deadline) >= 0;
}

static void raise_fault(struct co_master *m, struct co_node *n, uint16_t code)
{
	if (n->fault)
		return;	/* the first cause is kept */
	n->fault = 1;
	n->error_code = code;
	m->st.faults++;
}

enum co_402_state co_402_decode(uint16_t sw)
{
	if ((sw & 0x4Fu) == 0x00u)
		return CO402_NOT_READY;
	if ((sw & 0x4Fu) == 0x40u)
		return CO402_SWITCH_ON_DISABLED;
	if ((sw & 0x6Fu) == 0x21u)
		return CO402_READY_TO_SWITCH_ON;
	if ((sw & 0x6Fu) == 0x23u)
		return CO402_SWITCHED_ON;
	if ((sw & 0x6Fu) == 0x27u)
		return CO402_OPERATION_ENABLED;
	if ((sw & 0x6Fu) == 0x07u)
		return CO402_QUICK_STOP_ACTIVE;
	if ((sw & 0x4Fu) == 0x0Fu)
		return CO402_FAULT_REACTION_ACTIVE;
	if ((sw & 0x4Fu) == 0x08u)
		return CO402_FAULT;
	return CO402_UNKNOWN;
}

const char *co_402_name(enum co_402_state s)
{
	switch (s) {
	case CO402_NOT_READY: return "not ready to switch on";
	case CO402_SWITCH_ON_DISABLED: return "switch on disabled";
	case CO402_READY_TO_SWITCH_ON: return "ready to switch on";
	case CO402_SWITCHED_ON: return "switched on";
	case CO402_OPERATION_ENABLED: return "operation enabled";
	case CO402_QUICK_STOP_ACTIVE: return "quick stop active";
	case CO402_FAULT_REACTION_ACTIVE: return "fault reaction active";
	case CO402_FAULT: return "fault";
	default: return "unknown";
	}
}

const char *co_phase_name(enum co_node_phase p)
{
	switch (p) {
	case CO_PH_IDLE: return "idle";
	case CO_PH_RESET: return "nmt reset";
	case CO_PH_BOOT_WAIT: return "waiting for boot-up";
	case CO_PH_CONFIG: return "sdo configuration";
	case CO_PH_START: return "nmt start";
	case CO_PH_OPERATIONAL: return "operational";
	case CO_PH_FAILED: return "failed";
	default: return "unknown";
	}
}

int co_master_init(struct co_master *m, co_send_fn send, void *ctx, const struct co_config *cfg,
		   const uint8_t *node_ids, uint32_t n_nodes)
{
	struct co_master z = { 0 };

	*m = z;
	for (uint32_t i = 0; i < 128u; i++)
		m->index_of[i] = NO_NODE;
	if (!send || !cfg || n_nodes > CO_MAX_NODES || (n_nodes && !node_ids))
		return -1;
	m->send = send;
	m->ctx = ctx;
	m->cfg = *cfg;
	m->hb_consumer_cycles = ms_to_cycles(cfg->hb_consumer_ms, cfg->period_us);
	m->sdo_timeout_cycles = ms_to_cycles(cfg->sdo_timeout_ms, cfg->period_us);
	m->boot_timeout_cycles = ms_to_cycles(cfg->boot_timeout_ms, cfg->period_us);
	m->stamp_cycles = cfg->stamp_ms ? ms_to_cycles(cfg->stamp_ms, cfg->period_us) : 0u;
	for (uint32_t i = 0; i < n_nodes; i++) {
		uint8_t id = node_ids[i];

		if (id < 1u || id > 127u || m->index_of[id] != NO_NODE ||
		    (m->stamp_cycles && id == CO_MASTER_NODE_ID))
			return -1;
		m->index_of[id] = (uint8_t)i;
		m->node[i].node_id = id;
		m->node[i].phase = CO_PH_IDLE;
		m->node[i].nmt_state = 0xFFu;
	}
	m->n_nodes = n_nodes;
	return 0;
}

void co_master_start(struct co_master *m)
{
	for (uint32_t i = 0; i < m->n_nodes; i++) {
		struct co_node *n = &m->node[i];

		n->phase = CO_PH_RESET;
		n->tries = 0;
		n->sdo_busy = 0;
		n->hb_armed = 0;
	}
}

int co_master_stamp_due(const struct co_master *m)
{
	return m->stamp_cycles && m->cycle % m->stamp_cycles == 0u;
}

void co_master_time_stamp(struct co_master *m, uint32_t now_us)
{
	struct can_frame f;

	frame_clear(&f);
	f.id = CO_COB_TIME_STAMP;
	f.dlc = 4;
	wr_le(f.data, now_us, 4);
	if (tx(m, &f) == 0)
		m->st.stamps_sent++;
}

void co_master_set(struct co_master *m, uint32_t idx, int enable, int32_t target)
{
	if (idx >= m->n_nodes)
		return;
	m->node[idx].enable_req = enable ? 1u : 0u;
	m->node[idx].target = target;
}

const struct co_node *co_master_node(const struct co_master *m, uint32_t idx)
{
	return idx < m->n_nodes ? &m->node[idx] : NULL;
}

void co_master_stats(const struct co_master *m, struct co_stats *out)
{
	*out = m->st;
}

void co_master_renew_enable(struct co_master *m, uint32_t idx)
{
	if (idx < m->n_nodes)
		m->node[idx].enable_prev = 0;
}

void co_master_bus_off(struct co_master *m)
{
	m->st.bus_off++;
	for (uint32_t i = 0; i < m->n_nodes; i++) {
		struct co_node *n = &m->node[i];

		if (n->phase == CO_PH_OPERATIONAL)
			raise_fault(m, n, CO_ERR_BUS_OFF);
		n->tpdo_seen = 1;	/* the frames of this cycle are lost, not missing */
	}
}

/* ---- SDO client (expedited only) ----------------------------------- */

static int sdo_send_step(struct co_master *m, struct co_node *n)
{
	const struct cfg_step *s = &steps[n->step];
	struct can_frame f;

	frame_clear(&f);
	f.id = COB_SDO_RX + n->node_id;
	f.dlc = 8;
	if (s->kind == ST_WRITE) {
		uint32_t v = s->value == HB_VALUE ? m->cfg.hb_producer_ms : s->value;

		/* initiate download, expedited, size indicated: n = 4 - size */
		f.data[0] = (uint8_t)(0x23u | ((4u - s->size) << 2));
		wr_le(&f.data[4], v, s->size);
	} else {
		f.data[0] = 0x40u;	/* initiate upload */
	}
	wr_le(&f.data[1], s->index, 2);
	f.data[3] = s->sub;
	if (tx(m, &f))
		return -1;	/* tried again next cycle */
	n->sdo_busy = 1;
	n->deadline = m->cycle + m->sdo_timeout_cycles;
	m->st.sdo_req++;
	return 0;
}

static void config_failed(struct co_master *m, struct co_node *n)
{
	n->phase = CO_PH_FAILED;
	n->sdo_busy = 0;
	raise_fault(m, n, CO_ERR_CONFIG);
}

static void sdo_rx(struct co_master *m, struct co_node *n, const struct can_frame *f)
{
	const struct cfg_step *s;
	uint8_t cs;
	uint32_t v, size;

	if (f->dlc != 8u) {
		m->st.rx_bad++;
		return;
	}
	if (n->phase != CO_PH_CONFIG || !n->sdo_busy || n->step >= N_STEPS) {
		m->st.rx_ignored++;	/* late answer to a timed-out request */
		return;
	}
	s = &steps[n->step];
	if (rd_le(&f->data[1], 2) != s->index || f->data[3] != s->sub) {
		m->st.sdo_bad++;	/* an answer to another request */
		return;
	}
	cs = f->data[0];
	n->sdo_busy = 0;
	if (cs == 0x80u) {
		n->sdo_abort = rd_le(&f->data[4], 4);
		m->st.sdo_abort++;
		config_failed(m, n);
		return;
	}
	if (s->kind == ST_WRITE) {
		if (cs != 0x60u) {
			m->st.sdo_bad++;
			config_failed(m, n);
			return;
		}
	} else {
		/* initiate upload response: scs 2, expedited (e) required */
		if ((cs & 0xE0u) != 0x40u || !(cs & 0x02u)) {
			m->st.sdo_bad++;	/* segmented transfers are not supported */
			config_failed(m, n);
			return;
		}
		size = (cs & 0x01u) ? 4u - ((cs >> 2) & 3u) : 4u;
		v = rd_le(&f->data[4], size);
		if ((v & s->mask) != ((s->value + (s->node_rel ? n->node_id : 0u)) & s->mask)) {
			m->st.sdo_bad++;	/* wrong mode or mapping */
			config_failed(m, n);
			return;
		}
	}
	m->st.sdo_ok++;
	n->tries = 0;
	n->step++;
	if (n->step >= N_STEPS)
		n->phase = CO_PH_START;
}

/* ---- receive ------------------------------------------------------- */

void co_master_rx(struct co_master *m, const struct can_frame *f)
{
	uint32_t fn, id;
	struct co_node *n;

	m->st.rx_frames++;
	if (f->dlc > 8u || f->id > 0x7FFu) {
		m->st.rx_bad++;
		return;
	}
	fn = f->id & 0x780u;	/* function code */
	id = f->id & 0x7Fu;	/* node id */
	if (fn == COB_NMT || (fn == COB_SYNC && id == 0u) || id == 0u || m->index_of[id] == NO_NODE ||
	    fn == COB_RPDO1 || fn == COB_SDO_RX) {
		m->st.rx_ignored++;	/* NMT, SYNC, other nodes, other masters' requests */
		return;
	}
	n = &m->node[m->index_of[id]];
	if (f->rtr) {
		m->st.rx_bad++;	/* no remote frames expected from a node */
		return;
	}
	switch (fn) {
	case COB_EMCY: {
		uint16_t code;

		if (f->dlc < 3u) {
			m->st.rx_bad++;
			return;
		}
		code = (uint16_t)rd_le(&f->data[0], 2);
		n->emcy_last = code;
		if (code) {	/* 0x0000: error reset / no error */
			m->st.emcy++;
			raise_fault(m, n, code);
		}
		return;
	}
	case COB_TPDO1:
		if (f->dlc < 6u) {
			m->st.rx_bad++;
			return;
		}
		if (n->phase != CO_PH_OPERATIONAL) {
			m->st.rx_ignored++;
			return;
		}
		n->statusword = (uint16_t)rd_le(&f->data[0], 2);
		n->pos_actual = (int32_t)rd_le(&f->data[2], 4);
		n->pos_valid = 1;
		n->state402 = (uint8_t)co_402_decode(n->statusword);
		n->tpdo_seen = 1;
		n->tpdo_count++;
		m->st.tpdo_rx++;
		return;
	case COB_SDO_TX:
		sdo_rx(m, n, f);
		return;
	case COB_HB: {
		uint8_t state;

		if (f->dlc < 1u) {
			m->st.rx_bad++;
			return;
		}
		state = f->data[0] & 0x7Fu;
		m->st.hb_rx++;
		n->nmt_state = state;
		n->hb_last = m->cycle;
		if (state != 0u) {
			if (n->phase == CO_PH_OPERATIONAL)
				n->hb_armed = 1;
			return;
		}
		/* boot-up */
		m->st.bootups++;
		if (n->phase == CO_PH_BOOT_WAIT || n->phase == CO_PH_CONFIG || n->phase == CO_PH_START ||
		    n->phase == CO_PH_OPERATIONAL) {
			if (n->phase == CO_PH_OPERATIONAL)
				raise_fault(m, n, CO_ERR_RESTARTED);
			/* (re)configure: the node is pre-operational now */
			n->phase = CO_PH_CONFIG;
			n->step = 0;
			n->tries = 0;
			n->sdo_busy = 0;
			n->hb_armed = 0;
			n->pos_valid = 0;
			n->state402 = CO402_UNKNOWN;
		}
		return;
	}
	default:
		m->st.rx_ignored++;
		return;
	}
}

/* ---- cycle --------------------------------------------------------- */

static void startup_step(struct co_master *m, struct co_node *n)
{
	struct can_frame f;

	switch (n->phase) {
	case CO_PH_RESET:
		frame_clear(&f);
		f.id = COB_NMT;
		f.dlc = 2;
		f.data[0] = NMT_RESET_COMM;
		f.data[1] = n->node_id;
		if (tx(m, &f))
			return;
		m->st.nmt_sent++;
		n->phase = CO_PH_BOOT_WAIT;
		n->deadline = m->cycle + m->boot_timeout_cycles;
		return;
	case CO_PH_BOOT_WAIT:
		if (!expired(m, n->deadline))
			return;
		if (++n->tries > m->cfg.boot_retries) {
			n->phase = CO_PH_FAILED;
			raise_fault(m, n, CO_ERR_BOOT_TIMEOUT);
		} else {
			n->phase = CO_PH_RESET;
		}
		return;
	case CO_PH_CONFIG:
		if (n->sdo_busy) {
			if (!expired(m, n->deadline))
				return;
			n->sdo_busy = 0;
			m->st.sdo_timeout++;
			if (++n->tries > m->cfg.sdo_retries) {
				config_failed(m, n);
				return;
			}
		}
		if (n->step < N_STEPS)
			(void)sdo_send_step(m, n);
		return;
	case CO_PH_START:
		frame_clear(&f);
		f.id = COB_NMT;
		f.dlc = 2;
		f.data[0] = NMT_START;
		f.data[1] = n->node_id;
		if (tx(m, &f))
			return;
		m->st.nmt_sent++;
		n->phase = CO_PH_OPERATIONAL;
		n->hb_last = m->cycle;
		n->hb_armed = 1;
		n->tpdo_seen = 1;	/* no TPDO expected before the first SYNC */
		n->fault_reset = 0;
		return;
	default:
		return;
	}
}

static uint16_t controlword(struct co_master *m, struct co_node *n)
{
	int rising = n->enable_req && !n->enable_prev;

	n->enable_prev = n->enable_req;
	if (rising && n->fault) {
		n->fault = 0;	/* a new enable request acknowledges the fault */
		n->error_code = 0;
	}
	if (rising && (n->state402 == CO402_FAULT))
		n->fault_reset = 1;
	if (n->fault_reset) {
		n->fault_reset = 0;
		return CO_CW_FAULT_RESET;	/* rising edge of bit 7 (the last word had it clear) */
	}
	if (n->state402 == CO402_FAULT && !n->fault && n->enable_req)
		raise_fault(m, n, n->emcy_last ? n->emcy_last : CO_ERR_DRIVE_FAULT);
	if (!n->enable_req || n->fault)
		return n->state402 == CO402_QUICK_STOP_ACTIVE ? CO_CW_DISABLE_VOLTAGE : CO_CW_SHUTDOWN;
	switch (n->state402) {
	case CO402_READY_TO_SWITCH_ON:
		return CO_CW_SWITCH_ON;
	case CO402_SWITCHED_ON:
	case CO402_OPERATION_ENABLED:
		return CO_CW_ENABLE_OPERATION;
	case CO402_QUICK_STOP_ACTIVE:
		return CO_CW_DISABLE_VOLTAGE;
	default:	/* switch on disabled, not ready, fault reaction, unknown */
		return CO_CW_SHUTDOWN;
	}
}

static void send_rpdo(struct co_master *m, struct co_node *n)
{
	struct can_frame f;
	uint16_t cw = controlword(m, n);
	int32_t tgt;

	/* The target follows the drive until it runs enabled, so that the
	 * transition to operation enabled never makes it jump. */
	if (n->state402 == CO402_OPERATION_ENABLED && cw == CO_CW_ENABLE_OPERATION)
		tgt = n->target;
	else
		tgt = n->pos_valid ? n->pos_actual : n->target;
	frame_clear(&f);
	f.id = COB_RPDO1 + n->node_id;
	f.dlc = 6;
	wr_le(&f.data[0], cw, 2);
	wr_le(&f.data[2], (uint32_t)tgt, 4);
	if (tx(m, &f)) {
		m->st.rpdo_missed++;
		return;
	}
	n->controlword = cw;
	n->target_sent = tgt;
	m->st.rpdo_sent++;
}

void co_master_cycle(struct co_master *m)
{
	struct can_frame f;
	uint32_t missing = 0, operational = 0;

	m->cycle++;
	m->st.cycles++;
	for (uint32_t i = 0; i < m->n_nodes; i++) {
		struct co_node *n = &m->node[i];

		if (n->phase == CO_PH_OPERATIONAL) {
			if (!n->tpdo_seen)
				missing++;
			if (n->hb_armed && m->cycle - n->hb_last > m->hb_consumer_cycles) {
				n->hb_armed = 0;	/* re-armed by the next heartbeat */
				m->st.hb_timeouts++;
				raise_fault(m, n, CO_ERR_HEARTBEAT);
			}
		} else if (n->phase == CO_PH_FAILED && n->enable_req && !n->enable_prev) {
			n->phase = CO_PH_RESET;	/* a new enable request retries the start-up */
			n->tries = 0;
			n->fault = 0;	/* and acknowledges the fault */
			n->error_code = 0;
		}
		if (n->phase != CO_PH_OPERATIONAL)
			n->enable_prev = n->enable_req;
		startup_step(m, n);
	}
	m->st.pdo_missing += missing;
	m->st.pdo_missing_last = missing;
	if (missing > m->st.pdo_missing_max)
		m->st.pdo_missing_max = missing;

	for (uint32_t i = 0; i < m->n_nodes; i++) {
		struct co_node *n = &m->node[i];

		if (n->phase != CO_PH_OPERATIONAL)
			continue;
		operational++;
		send_rpdo(m, n);
	}
	m->st.nodes_operational = operational;

	frame_clear(&f);
	f.id = COB_SYNC;
	if (tx(m, &f)) {
		m->st.sync_missed++;
		return;
	}
	m->st.sync_sent++;
	for (uint32_t i = 0; i < m->n_nodes; i++)
		if (m->node[i].phase == CO_PH_OPERATIONAL)
			m->node[i].tpdo_seen = 0;
}
