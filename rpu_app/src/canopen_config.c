/* SPDX-License-Identifier: MIT */
/*
 * canopen_config.c - the start-up half of the CANopen master (see
 * canopen_master.h): NMT reset communication, the boot-up wait (retried),
 * the SDO configuration of a CiA 402 drive in CSP (expedited transfers,
 * one outstanding per node, each with its timeout and retries), and the
 * NMT start (confirmed by canopen_master.c, sent again here). No
 * transport, no globals, no allocation, no library calls.
 */
#include <stddef.h>
#include <stdint.h>

#include "canopen_internal.h"

/* One step of the SDO configuration. */
enum { ST_WRITE, ST_READ, ST_COB_ID };
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
	{ ST_COB_ID, 1, 0, 1, 0x1800, COB_TPDO1, 0 },		/* TPDO1 COB-ID */
	{ ST_COB_ID, 1, 0, 1, 0x1400, COB_RPDO1, 0 },		/* RPDO1 COB-ID */
	{ ST_WRITE, 2, 1, 0, 0x1800, 1u, 0 },			/* TPDO1 on every SYNC */
	{ ST_WRITE, 2, 1, 0, 0x1400, 1u, 0 },			/* RPDO1 applied at SYNC */
	{ ST_WRITE, 0, 2, 0, 0x1017, HB_VALUE, 0 },		/* heartbeat producer time */
};
#define N_STEPS (sizeof(steps) / sizeof(steps[0]))

/* PDO COB-ID (CiA 301, 0x1400/0x1800 sub 1): bit 31 0 = valid, bit 30
 * RTR (not used either way), bit 29 1 = 29-bit identifier, bits 0-10 the
 * 11-bit identifier and bits 11-28 then 0. The master speaks 11-bit
 * identifiers only and takes a PDO on its default identifier only. */
#define COB_VALID_BIT 0x80000000u
#define COB_29BIT 0x20000000u
#define COB_HIGH_BITS 0x1FFFF800u

uint32_t co_config_steps(void)
{
	return (uint32_t)N_STEPS;
}

const char *co_cfg_reason_name(enum co_cfg_reason r)
{
	switch (r) {
	case CO_CFG_OK: return "none";
	case CO_CFG_SDO_ABORT: return "SDO transfer aborted by the node";
	case CO_CFG_SDO_TIMEOUT: return "no SDO answer";
	case CO_CFG_SDO_PROTOCOL: return "SDO answer not an expedited transfer";
	case CO_CFG_VALUE: return "value other than the one needed";
	case CO_CFG_COB_INVALID: return "PDO not valid (COB-ID bit 31)";
	case CO_CFG_COB_29BIT: return "29-bit identifier (COB-ID bit 29) not supported";
	case CO_CFG_COB_BITS: return "COB-ID bits 11-28 set";
	case CO_CFG_COB_ID: return "COB-ID not the PDO's default identifier";
	default: return "unknown";
	}
}

void co_config_restart(struct co_node *n)
{
	n->phase = CO_PH_CONFIG;
	n->step = 0;
	n->tries = 0;
	n->sdo_busy = 0;
}

static int sdo_send_step(struct co_master *m, struct co_node *n)
{
	const struct cfg_step *s = &steps[n->step];
	struct can_frame f;

	co_frame_clear(&f);
	f.id = COB_SDO_RX + n->node_id;
	f.dlc = 8;
	if (s->kind == ST_WRITE) {
		uint32_t v = s->value == HB_VALUE ? m->cfg.hb_producer_ms : s->value;

		/* initiate download, expedited, size indicated: n = 4 - size */
		f.data[0] = (uint8_t)(0x23u | ((4u - s->size) << 2));
		co_wr_le(&f.data[4], v, s->size);
	} else {
		f.data[0] = 0x40u;	/* initiate upload */
	}
	co_wr_le(&f.data[1], s->index, 2);
	f.data[3] = s->sub;
	if (co_tx(m, &f))
		return -1;	/* tried again next cycle */
	n->sdo_busy = 1;
	n->deadline = m->cycle + m->sdo_timeout_cycles;
	m->st.sdo_req++;
	return 0;
}

static void config_failed(struct co_master *m, struct co_node *n, enum co_cfg_reason why, uint32_t value)
{
	const struct cfg_step *s = &steps[n->step < N_STEPS ? n->step : 0];

	n->phase = CO_PH_FAILED;
	n->sdo_busy = 0;
	n->cfg_reason = (uint8_t)why;
	n->cfg_index = s->index;
	n->cfg_sub = s->sub;
	n->cfg_value = value;
	co_raise_fault(m, n, why >= CO_CFG_COB_INVALID ? CO_ERR_PDO_COB_ID : CO_ERR_CONFIG);
}

/* The reason a PDO COB-ID is refused, CO_CFG_OK if it is taken. */
static enum co_cfg_reason cob_id_check(uint32_t v, uint32_t want)
{
	if (v & COB_VALID_BIT)
		return CO_CFG_COB_INVALID;
	if (v & COB_29BIT)
		return CO_CFG_COB_29BIT;
	if (v & COB_HIGH_BITS)
		return CO_CFG_COB_BITS;
	if ((v & 0x7FFu) != want)
		return CO_CFG_COB_ID;
	return CO_CFG_OK;
}

void co_sdo_rx(struct co_master *m, struct co_node *n, const struct can_frame *f)
{
	const struct cfg_step *s;
	uint8_t cs;
	uint32_t v, size, want;

	if (f->dlc != 8u) {
		m->st.rx_bad++;
		return;
	}
	if (n->phase != CO_PH_CONFIG || !n->sdo_busy || n->step >= N_STEPS) {
		m->st.rx_ignored++;	/* late answer to a timed-out request */
		return;
	}
	s = &steps[n->step];
	if (co_rd_le(&f->data[1], 2) != s->index || f->data[3] != s->sub) {
		m->st.sdo_bad++;	/* an answer to another request */
		return;
	}
	cs = f->data[0];
	n->sdo_busy = 0;
	if (cs == 0x80u) {
		n->sdo_abort = co_rd_le(&f->data[4], 4);
		m->st.sdo_abort++;
		config_failed(m, n, CO_CFG_SDO_ABORT, n->sdo_abort);
		return;
	}
	if (s->kind == ST_WRITE) {
		if (cs != 0x60u) {
			m->st.sdo_bad++;
			config_failed(m, n, CO_CFG_SDO_PROTOCOL, cs);
			return;
		}
	} else {
		/* initiate upload response: scs 2, expedited (e) required */
		if ((cs & 0xE0u) != 0x40u || !(cs & 0x02u)) {
			m->st.sdo_bad++;	/* segmented transfers are not supported */
			config_failed(m, n, CO_CFG_SDO_PROTOCOL, cs);
			return;
		}
		size = (cs & 0x01u) ? 4u - ((cs >> 2) & 3u) : 4u;
		v = co_rd_le(&f->data[4], size);
		want = (s->value + (s->node_rel ? n->node_id : 0u));
		if (s->kind == ST_COB_ID) {
			enum co_cfg_reason why = cob_id_check(v, want);

			if (why != CO_CFG_OK) {
				m->st.sdo_bad++;
				config_failed(m, n, why, v);
				return;
			}
		} else if ((v & s->mask) != (want & s->mask)) {
			m->st.sdo_bad++;	/* wrong mode or mapping */
			config_failed(m, n, CO_CFG_VALUE, v);
			return;
		}
	}
	m->st.sdo_ok++;
	n->tries = 0;
	n->step++;
	if (n->step >= N_STEPS) {
		n->phase = CO_PH_START;
		n->start_tries = 0;
	}
}

static int send_nmt(struct co_master *m, struct co_node *n, uint8_t cs)
{
	struct can_frame f;

	co_frame_clear(&f);
	f.id = COB_NMT;
	f.dlc = 2;
	f.data[0] = cs;
	f.data[1] = n->node_id;
	if (co_tx(m, &f))
		return -1;
	m->st.nmt_sent++;
	return 0;
}

void co_startup_step(struct co_master *m, struct co_node *n)
{
	switch (n->phase) {
	case CO_PH_RESET:
		if (send_nmt(m, n, NMT_RESET_COMM))
			return;
		n->phase = CO_PH_BOOT_WAIT;
		n->deadline = m->cycle + m->boot_timeout_cycles;
		return;
	case CO_PH_BOOT_WAIT:
		if (!co_expired(m, n->deadline))
			return;
		if (++n->tries > m->cfg.boot_retries) {
			n->phase = CO_PH_FAILED;
			co_raise_fault(m, n, CO_ERR_BOOT_TIMEOUT);
		} else {
			n->phase = CO_PH_RESET;
		}
		return;
	case CO_PH_CONFIG:
		if (n->sdo_busy) {
			if (!co_expired(m, n->deadline))
				return;
			n->sdo_busy = 0;
			m->st.sdo_timeout++;
			if (++n->tries > m->cfg.sdo_retries) {
				config_failed(m, n, CO_CFG_SDO_TIMEOUT, 0);
				return;
			}
		}
		if (n->step < N_STEPS)
			(void)sdo_send_step(m, n);
		return;
	case CO_PH_START:
		if (send_nmt(m, n, NMT_START))
			return;	/* TX full: sent next cycle */
		n->phase = CO_PH_OPERATIONAL;
		n->confirmed = 0;	/* by its first TPDO1 or a heartbeat 0x05 */
		n->hb_confirmed = 0;	/* its heartbeats may predate the start */
		n->nmt_lost = 0;
		n->deadline = m->cycle + m->start_timeout_cycles;
		n->hb_last = m->cycle;
		n->hb_armed = 1;
		n->tpdo_seen = 1;	/* no TPDO expected before the first SYNC */
		n->pdo_silent = 0;
		return;
	default:
		return;
	}
}
