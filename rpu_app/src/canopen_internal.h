/* SPDX-License-Identifier: MIT */
#ifndef RPU_CANOPEN_INTERNAL_H
#define RPU_CANOPEN_INTERNAL_H

/*
 * What the two halves of the CANopen master share (not an API):
 * canopen_master.c (frames in, the cycle, NMT and heartbeat supervision,
 * the CiA 402 controlword and fault reset) and canopen_config.c (the
 * start-up: NMT reset, boot-up wait, SDO configuration, NMT start).
 */
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
#define NMT_STOP 0x02u
#define NMT_ENTER_PREOP 0x80u
#define NMT_RESET_NODE 0x81u
#define NMT_RESET_COMM 0x82u

/* heartbeat states (byte 0, bits 0-6) */
#define NMT_ST_BOOTUP 0x00u
#define NMT_ST_STOPPED 0x04u
#define NMT_ST_OPERATIONAL 0x05u
#define NMT_ST_PREOP 0x7Fu

static inline uint32_t co_rd_le(const uint8_t *p, uint32_t n)
{
	uint32_t v = 0;

	for (uint32_t i = 0; i < n && i < 4u; i++)
		v |= (uint32_t)p[i] << (8u * i);
	return v;
}

static inline void co_wr_le(uint8_t *p, uint32_t v, uint32_t n)
{
	for (uint32_t i = 0; i < n && i < 4u; i++)
		p[i] = (uint8_t)(v >> (8u * i));
}

static inline void co_frame_clear(struct can_frame *f)
{
	f->id = 0;
	f->dlc = 0;
	f->rtr = 0;
	for (uint32_t i = 0; i < 8u; i++)
		f->data[i] = 0;
}

static inline int co_tx(struct co_master *m, const struct can_frame *f)
{
	if (m->send(m->ctx, f)) {
		m->st.tx_busy++;
		return -1;
	}
	return 0;
}

static inline int co_expired(const struct co_master *m, uint32_t deadline)
{
	return (int32_t)(m->cycle - deadline) >= 0;
}

/* Latch an axis fault; the first cause is kept. */
static inline void co_raise_fault(struct co_master *m, struct co_node *n, uint16_t code)
{
	if (n->fault)
		return;
	n->fault = 1;
	n->error_code = code;
	m->st.faults++;
}

/* canopen_drive.c: the acknowledgement of an axis's faults (the
 * operator's: co_master_acknowledge), and the controlword of this cycle's
 * RPDO. */
void co_acknowledge(struct co_master *m, struct co_node *n);
uint16_t co_controlword(struct co_master *m, struct co_node *n);

/* canopen_config.c: the start-up step of one node in this cycle (NMT
 * reset, boot-up wait, SDO configuration, NMT start), and the SDO answer
 * of a node. */
void co_startup_step(struct co_master *m, struct co_node *n);
void co_sdo_rx(struct co_master *m, struct co_node *n, const struct can_frame *f);
/* The configuration restarts from its first step (after a boot-up). */
void co_config_restart(struct co_node *n);
/* Number of SDO steps of a full configuration. */
uint32_t co_config_steps(void);

#endif
