/* SPDX-License-Identifier: MIT */
/*
 * canopen_master.c - CANopen master for CiA 402 drives in CSP (see
 * canopen_master.h): frames in, the cycle, the supervision of operational
 * nodes (heartbeat, NMT state, TPDO silence, NMT start confirmation) and
 * the CiA 402 controlword with its fault reset. The start-up (NMT reset,
 * SDO configuration, NMT start) is canopen_config.c. No transport, no
 * globals, no allocation, no library calls: built into the firmware and,
 * unchanged, into the host unit tests.
 */
#include <stddef.h>
#include <stdint.h>

#include "canopen_internal.h"

#define NO_NODE 0xFFu

static uint32_t ms_to_cycles(uint32_t ms, uint32_t period_us)
{
	uint32_t c;

	if (!period_us)
		period_us = 1000u;
	c = (uint32_t)(((uint64_t)ms * 1000u + period_us - 1u) / period_us);
	return c ? c : 1u;
}

const char *co_nmt_name(uint8_t st)
{
	switch (st) {
	case NMT_ST_BOOTUP: return "boot-up";
	case NMT_ST_STOPPED: return "stopped";
	case NMT_ST_OPERATIONAL: return "operational";
	case NMT_ST_PREOP: return "pre-operational";
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

static uint32_t or_default(uint32_t v, uint32_t def)
{
	return v ? v : def;
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
	m->start_timeout_cycles =
		ms_to_cycles(or_default(cfg->start_timeout_ms, CO_DEFAULT_START_TIMEOUT_MS), cfg->period_us);
	m->start_retries = or_default(cfg->start_retries, CO_DEFAULT_START_RETRIES);
	m->pdo_timeout_cycles = or_default(cfg->pdo_timeout_cycles, CO_DEFAULT_PDO_TIMEOUT_CYCLES);
	m->fault_reset_cycles =
		ms_to_cycles(or_default(cfg->fault_reset_ms, CO_DEFAULT_FAULT_RESET_MS), cfg->period_us);
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

	co_frame_clear(&f);
	f.id = CO_COB_TIME_STAMP;
	f.dlc = 4;
	co_wr_le(f.data, now_us, 4);
	if (co_tx(m, &f) == 0)
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

void co_master_acknowledge(struct co_master *m, uint32_t idx)
{
	if (idx < m->n_nodes)
		m->node[idx].ack_req = 1;
}

void co_master_bus_off(struct co_master *m)
{
	m->st.bus_off++;
	for (uint32_t i = 0; i < m->n_nodes; i++) {
		struct co_node *n = &m->node[i];

		if (n->phase == CO_PH_OPERATIONAL)
			co_raise_fault(m, n, CO_ERR_BUS_OFF);
		n->tpdo_seen = 1;	/* the frames of this cycle are lost, not missing */
	}
}

/* ---- supervision ---------------------------------------------------- */

/* A fault that names a cause replaces a latched TPDO timeout (its
 * symptom: a node that went silent or left Operational stops its TPDOs
 * long before its heartbeat says why); otherwise the first cause is kept. */
static void refine_fault(struct co_master *m, struct co_node *n, uint16_t code)
{
	if (n->fault && n->error_code == CO_ERR_PDO_TIMEOUT)
		n->error_code = code;
	else
		co_raise_fault(m, n, code);
}

/* The node reports (heartbeat) or was sent (another master's NMT) a state
 * other than Operational after its start was confirmed: it does not
 * follow the PDOs any more, its 402 state is unknown from here on. */
static void left_operational(struct co_master *m, struct co_node *n, uint8_t state)
{
	if (!n->nmt_lost)
		m->st.nmt_left++;
	n->nmt_lost = 1;
	n->state402 = CO402_UNKNOWN;
	n->reset_active = 0;
	refine_fault(m, n, state == NMT_ST_STOPPED ? CO_ERR_NMT_STOPPED : CO_ERR_NMT_PREOP);
}

/* An NMT state seen for an operational node: confirms its start, or
 * tells that it left Operational. */
static void nmt_state_seen(struct co_master *m, struct co_node *n, uint8_t state)
{
	if (n->phase != CO_PH_OPERATIONAL)
		return;
	if (state == NMT_ST_OPERATIONAL) {
		n->confirmed = 1;
		n->hb_confirmed = 1;
		return;
	}
	/* Until the node's own heartbeat has said Operational, one may still
	 * be the one it sent before it handled the NMT start: before the
	 * confirmation the start's own timeout decides; after a TPDO's (a
	 * heartbeat loses arbitration to the TPDOs of its SYNC, so it can
	 * come behind the first one), the node has left only if its TPDO
	 * fell silent since. */
	if (n->confirmed && (n->hb_confirmed || n->pdo_silent))
		left_operational(m, n, state);
}

static void rx_heartbeat(struct co_master *m, struct co_node *n, const struct can_frame *f)
{
	uint8_t state;

	if (f->dlc < 1u) {
		m->st.rx_bad++;
		return;
	}
	state = f->data[0] & 0x7Fu;
	if (state != NMT_ST_BOOTUP && state != NMT_ST_STOPPED && state != NMT_ST_OPERATIONAL &&
	    state != NMT_ST_PREOP) {
		m->st.rx_bad++;	/* no NMT state: not a heartbeat to trust */
		return;
	}
	m->st.hb_rx++;
	n->nmt_state = state;
	n->hb_last = m->cycle;
	if (state != NMT_ST_BOOTUP) {
		if (n->phase == CO_PH_OPERATIONAL)
			n->hb_armed = 1;
		nmt_state_seen(m, n, state);
		return;
	}
	/* boot-up */
	m->st.bootups++;
	if (n->phase == CO_PH_BOOT_WAIT || n->phase == CO_PH_CONFIG || n->phase == CO_PH_START ||
	    n->phase == CO_PH_OPERATIONAL) {
		if (n->phase == CO_PH_OPERATIONAL)
			co_raise_fault(m, n, CO_ERR_RESTARTED);
		/* (re)configure: the node is pre-operational now */
		co_config_restart(n);
		n->hb_armed = 0;
		n->pos_valid = 0;
		n->state402 = CO402_UNKNOWN;
		n->nmt_lost = 0;
		n->confirmed = 0;
		n->hb_confirmed = 0;
		n->reset_active = 0;
	}
}

/* An NMT command on the bus from another master (ours are not received
 * back): stop and enter pre-operational take the node out of Operational
 * at once; its next heartbeat will say so too. */
static void rx_foreign_nmt(struct co_master *m, const struct can_frame *f)
{
	uint8_t cs, id, state;

	if (f->dlc != 2u || f->rtr) {
		m->st.rx_bad++;
		return;
	}
	cs = f->data[0];
	id = f->data[1];
	if (cs == NMT_STOP)
		state = NMT_ST_STOPPED;
	else if (cs == NMT_ENTER_PREOP)
		state = NMT_ST_PREOP;
	else {
		m->st.rx_ignored++;	/* start, resets: the heartbeat / boot-up tells */
		return;
	}
	for (uint32_t i = 0; i < m->n_nodes; i++) {
		struct co_node *n = &m->node[i];

		if (id != 0u && id != n->node_id)
			continue;
		m->st.nmt_foreign++;
		n->nmt_state = state;
		if (n->phase == CO_PH_OPERATIONAL && n->confirmed)
			left_operational(m, n, state);
	}
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
	if (f->id == COB_NMT) {
		rx_foreign_nmt(m, f);
		return;
	}
	fn = f->id & 0x780u;	/* function code */
	id = f->id & 0x7Fu;	/* node id */
	if (fn == COB_NMT || id == 0u || m->index_of[id] == NO_NODE || fn == COB_RPDO1 || fn == COB_SDO_RX) {
		m->st.rx_ignored++;	/* SYNC, other nodes, other masters' requests */
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
		code = (uint16_t)co_rd_le(&f->data[0], 2);
		n->emcy_last = code;
		if (code) {	/* 0x0000: error reset / no error */
			m->st.emcy++;
			co_raise_fault(m, n, code);
		}
		return;
	}
	case COB_TPDO1:
		if (f->dlc < 6u) {
			m->st.rx_bad++;
			return;
		}
		if (n->phase != CO_PH_OPERATIONAL || n->nmt_lost) {
			m->st.rx_ignored++;
			return;
		}
		n->statusword = (uint16_t)co_rd_le(&f->data[0], 2);
		n->pos_actual = (int32_t)co_rd_le(&f->data[2], 4);
		n->pos_valid = 1;
		n->state402 = (uint8_t)co_402_decode(n->statusword);
		n->tpdo_seen = 1;
		n->confirmed = 1;	/* a TPDO: the node is operational */
		n->nmt_state = NMT_ST_OPERATIONAL;
		n->tpdo_count++;
		m->st.tpdo_rx++;
		return;
	case COB_SDO_TX:
		co_sdo_rx(m, n, f);
		return;
	case COB_HB:
		rx_heartbeat(m, n, f);
		return;
	default:
		m->st.rx_ignored++;
		return;
	}
}

/* ---- cycle --------------------------------------------------------- */

static void send_rpdo(struct co_master *m, struct co_node *n)
{
	struct can_frame f;
	uint16_t cw = co_controlword(m, n);
	int32_t tgt;

	/* The target follows the drive until it runs enabled, so that the
	 * transition to operation enabled never makes it jump. */
	if (n->state402 == CO402_OPERATION_ENABLED && cw == CO_CW_ENABLE_OPERATION)
		tgt = n->target;
	else
		tgt = n->pos_valid ? n->pos_actual : n->target;
	co_frame_clear(&f);
	f.id = COB_RPDO1 + n->node_id;
	f.dlc = 6;
	co_wr_le(&f.data[0], cw, 2);
	co_wr_le(&f.data[2], (uint32_t)tgt, 4);
	if (co_tx(m, &f)) {
		m->st.rpdo_missed++;	/* a reset word is sent again next cycle */
		return;
	}
	if (n->reset_active && (cw & CO_CW_FAULT_RESET))
		n->reset_sent = 1;
	n->controlword = cw;
	n->target_sent = tgt;
	m->st.rpdo_sent++;
}

/* One operational node at the start of a cycle: the NMT start's
 * confirmation, TPDO silence, the heartbeat consumer. Returns 1 when the
 * node's TPDO1 of the last SYNC is missing. */
static int supervise(struct co_master *m, struct co_node *n)
{
	int missing = !n->tpdo_seen;

	if (!n->confirmed) {
		if (co_expired(m, n->deadline)) {
			if (n->start_tries >= m->start_retries) {
				n->phase = CO_PH_FAILED;
				co_raise_fault(m, n, CO_ERR_NMT_START);
				return 0;
			}
			n->start_tries++;	/* NMT start lost: sent again this cycle */
			m->st.start_retries++;
			n->phase = CO_PH_START;
		}
		return 0;	/* no TPDO expected before the start is confirmed */
	}
	if (missing) {
		if (n->pdo_silent < 0xFFu)
			n->pdo_silent++;
		if (n->pdo_silent >= m->pdo_timeout_cycles && !n->fault) {
			m->st.pdo_timeouts++;
			co_raise_fault(m, n, CO_ERR_PDO_TIMEOUT);
		}
	} else {
		n->pdo_silent = 0;
	}
	if (n->hb_armed && m->cycle - n->hb_last > m->hb_consumer_cycles) {
		n->hb_armed = 0;	/* re-armed by the next heartbeat */
		m->st.hb_timeouts++;
		refine_fault(m, n, CO_ERR_HEARTBEAT);
	}
	return missing;
}

void co_master_supervise(struct co_master *m)
{
	uint32_t missing = 0;

	if (m->supervised)
		return;
	m->supervised = 1;
	m->cycle++;
	m->st.cycles++;
	for (uint32_t i = 0; i < m->n_nodes; i++)
		if (m->node[i].phase == CO_PH_OPERATIONAL)
			missing += (uint32_t)supervise(m, &m->node[i]);
	m->st.pdo_missing += missing;
	m->st.pdo_missing_last = missing;
	if (missing > m->st.pdo_missing_max)
		m->st.pdo_missing_max = missing;
}

void co_master_cycle(struct co_master *m)
{
	struct can_frame f;
	uint32_t operational = 0;

	co_master_supervise(m);	/* if the caller did not, after the frames */
	m->supervised = 0;
	for (uint32_t i = 0; i < m->n_nodes; i++) {
		struct co_node *n = &m->node[i];

		if (n->ack_req) {
			n->ack_req = 0;
			co_acknowledge(m, n);
			if (n->phase == CO_PH_OPERATIONAL && n->nmt_lost) {
				/* out of Operational: NMT start again, then the
				 * enable sequence (and a fault reset if the drive
				 * turns out to be in Fault) */
				n->ack_wait = 1;
				n->nmt_lost = 0;
				n->start_tries = 0;
				n->phase = CO_PH_START;
			} else if (n->phase == CO_PH_FAILED) {
				n->phase = CO_PH_RESET;	/* the start-up from its beginning */
				n->tries = 0;
				n->cfg_reason = CO_CFG_OK;
			}
		}
		co_startup_step(m, n);
	}

	for (uint32_t i = 0; i < m->n_nodes; i++) {
		struct co_node *n = &m->node[i];

		if (n->phase != CO_PH_OPERATIONAL)
			continue;
		operational++;
		send_rpdo(m, n);
	}
	m->st.nodes_operational = operational;

	co_frame_clear(&f);
	f.id = COB_SYNC;
	if (co_tx(m, &f)) {
		m->st.sync_missed++;
		return;
	}
	m->st.sync_sent++;
	for (uint32_t i = 0; i < m->n_nodes; i++)
		if (m->node[i].phase == CO_PH_OPERATIONAL)
			m->node[i].tpdo_seen = 0;
}
