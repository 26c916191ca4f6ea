/* SPDX-License-Identifier: MIT */
#ifndef CO_TESTBUS_H
#define CO_TESTBUS_H
/*
 * The scripted bus of the CANopen master's host unit tests
 * (test_canopen_master.c, test_canopen_faults.c; co_testbus.c): the
 * master's frames reach the drives at once, the drives' answers reach the
 * master at the start of the next cycle (deliver), one cycle is 1 ms.
 */
#include <stdint.h>
#include <stdio.h>

#include "canopen_master.h"

extern int failed, checks;

#define CHECK(c) do { checks++; if (!(c)) { failed++; \
	fprintf(stderr, "%s:%d: CHECK failed: %s\n", __FILE__, __LINE__, #c); } } while (0)
#define CHECK_EQ(a, b) do { long long a_ = (long long)(a), b_ = (long long)(b); checks++; \
	if (a_ != b_) { failed++; fprintf(stderr, "%s:%d: %s == %lld, expected %s == %lld\n", \
	__FILE__, __LINE__, #a, a_, #b, b_); } } while (0)

#define QMAX 256
#define SENT_LOG_MAX 4096
extern struct can_frame to_master[QMAX];	/* drives -> master, next cycle */
extern unsigned n_to_master;
extern int tx_busy_left;			/* the master's TX refuses this many sends */
extern unsigned sent_log_n;
extern struct can_frame sent_log[SENT_LOG_MAX];

struct drive {
	uint8_t id;
	int present;		/* answers at all */
	int boots;		/* sends boot-up after NMT reset */
	int nmt;		/* 0 boot, 4 stopped, 5 operational, 127 pre-op */
	int hb_silent;		/* stops heartbeats (and everything else) */
	uint16_t sw;		/* statusword */
	uint16_t cw;		/* last controlword applied */
	int8_t mode, mode_disp;
	uint32_t map1a00[3], map1600[3];
	uint32_t cob1800, cob1400;
	uint8_t tt1800, tt1400;
	uint16_t hb_ms;
	int32_t pos, target;
	int32_t rpdo_target;
	uint16_t rpdo_cw;
	int rpdo_new;
	uint32_t abort_index;	/* SDO abort for this index (0: none) */
	uint32_t cycle;
	uint16_t pending_emcy;
	int reset_delay;	/* SYNCs from a fault reset's edge to leaving Fault, bit 7
				 * held all along (dropped: the reset is abandoned); -1 never */
	int reset_count;	/* SYNCs left of a running reset (-1: never ends) */
	int drop_nmt_start;	/* this many NMT starts lost on the bus */
	int tpdo_mute;		/* operational, heartbeat on, but no TPDO */
	unsigned nmt_starts;	/* NMT starts received */
	unsigned cw_hist_n;
	uint16_t cw_hist[64];	/* distinct controlwords applied, in order */
};

#define ND 3

#define ND 3
extern struct drive drv[ND];	/* node ids 1, 2, 5 (5 is never the master's) */
extern const struct co_config CFG;

void q_push(uint32_t id, uint8_t dlc, const uint8_t *data);
void drive_reset(struct drive *d, uint8_t id);
void drive_fault(struct drive *d, uint16_t code);	/* Fault, EMCY with code */
/* An NMT command from another master on the bus: the drives get it at
 * once, the master with the next cycle's frames. */
void other_master_nmt(uint8_t cs, uint8_t node);
void drive_rx(struct drive *d, const struct can_frame *f);
int fake_send(void *ctx, const struct can_frame *f);
void drives_tick(void);			/* once per cycle: heartbeats */
void deliver(struct co_master *m);	/* the drives' answers to the master */
void run(struct co_master *m, int cycles);
void setup(struct co_master *m, int n);	/* n nodes, started */
void enable_all(struct co_master *m, int on);
void bring_up(struct co_master *m, int n);	/* ... and in operation enabled */

#endif
