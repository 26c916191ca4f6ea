/* SPDX-License-Identifier: MIT */
/*
 * Host unit test of the CANopen master's supervision (issue 33): every
 * way a drive stops following is an axis fault within a stated number of
 * cycles, and a fault reset works with drives that take their time. Built
 * with -fsanitize=address,undefined against the scripted drives of
 * co_testbus.c (test_rpu_canopen_host.py). One cycle is 1 ms; the
 * drives' answers to a cycle's SYNC reach the master at the start of the
 * next cycle.
 */
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "co_testbus.h"

#define PDO_TIMEOUT ((int)CO_DEFAULT_PDO_TIMEOUT_CYCLES)	/* cycles without TPDO1 */
#define START_TIMEOUT ((int)CO_DEFAULT_START_TIMEOUT_MS)	/* cycles (1 ms each) */
#define START_RETRIES ((int)CO_DEFAULT_START_RETRIES)
#define RESET_TIMEOUT ((int)CO_DEFAULT_FAULT_RESET_MS)	/* cycles */

/* Cycles until node idx is faulted (at most limit; -1 if not). */
static int cycles_to_fault(struct co_master *m, uint32_t idx, int limit)
{
	for (int c = 1; c <= limit; c++) {
		run(m, 1);
		if (co_master_node(m, idx)->fault)
			return c;
	}
	return -1;
}

/* Cycles until every node of m is in operation enabled without a fault. */
static int cycles_to_enabled(struct co_master *m, int limit)
{
	for (int c = 1; c <= limit; c++) {
		int all = 1;

		enable_all(m, 1);
		run(m, 1);
		for (uint32_t i = 0; i < m->n_nodes; i++)
			all &= co_master_node(m, i)->state402 == CO402_OPERATION_ENABLED &&
				!co_master_node(m, i)->fault;
		if (all)
			return c;
	}
	return -1;
}

/* The operator's acknowledgement with the enable held (ampctl resume). */
static void resume(struct co_master *m)
{
	for (uint32_t i = 0; i < m->n_nodes; i++)
		co_master_acknowledge(m, i);
}

/* A drive that leaves Operational on its own (its communication error
 * reaction, CiA 301 0x1029) and says so in its heartbeat: the axis faults
 * in the cycle that reads the heartbeat, with the state's code. */
static void test_heartbeat_not_operational(uint8_t state, uint16_t code)
{
	struct co_master m;
	int c;

	bring_up(&m, 2);
	drv[0].nmt = state;
	q_push(0x700u + drv[0].id, 1, &state);	/* its heartbeat, right away */
	c = cycles_to_fault(&m, 0, 1000);
	printf("nmt: heartbeat 0x%02x: axis faulted after %d cycle(s), error 0x%04x\n", state, c,
	       (unsigned)co_master_node(&m, 0)->error_code);
	CHECK_EQ(c, 1);
	CHECK_EQ(co_master_node(&m, 0)->error_code, code);
	CHECK_EQ(co_master_node(&m, 0)->nmt_lost, 1);
	CHECK_EQ(co_master_node(&m, 0)->nmt_state, state);
	CHECK(co_master_node(&m, 0)->state402 != CO402_OPERATION_ENABLED);
	CHECK_EQ(co_master_node(&m, 1)->fault, 0);
	/* latched while it stays there, whatever the TPDO silence adds, and
	 * the enable request off for a cycle (Linux, as a program ends in
	 * fault) is no acknowledgement */
	run(&m, 20);
	enable_all(&m, 0);
	run(&m, 1);
	enable_all(&m, 1);
	run(&m, 30);
	CHECK_EQ(co_master_node(&m, 0)->error_code, code);
	CHECK_EQ(co_master_node(&m, 0)->nmt_lost, 1);
	CHECK_EQ(drv[0].nmt, state);
	CHECK_EQ(m.st.faults, 1);
	CHECK_EQ(m.st.nmt_left, 1);
	/* one acknowledgement: NMT start again, the enable sequence, enabled */
	resume(&m);
	c = cycles_to_enabled(&m, 100);
	printf("nmt: back in operation enabled %d cycles after the acknowledgement\n", c);
	CHECK(c > 0 && c < 20);
	CHECK_EQ(drv[0].nmt, 5);
	CHECK_EQ(co_master_node(&m, 0)->error_code, 0);
	CHECK_EQ(co_master_node(&m, 0)->nmt_lost, 0);
	CHECK_EQ(co_master_node(&m, 0)->nmt_state, 5);	/* its TPDO says so before its heartbeat */
}

/* The same drive leaving silently between its heartbeats (20 ms apart
 * here): the TPDO silence faults the axis first, the heartbeat then names
 * the state. */
static void test_preop_between_heartbeats(void)
{
	struct co_master m;
	int c;

	bring_up(&m, 1);
	q_push(0x700u + drv[0].id, 1, (const uint8_t[]){ 5 });	/* its last heartbeat in Operational */
	drv[0].nmt = 127;
	drv[0].hb_ms = 20;	/* the next one 20 cycles away (the consumer waits 30) */
	drv[0].cycle = 0;
	c = cycles_to_fault(&m, 0, 1000);
	CHECK_EQ(c, 1 + PDO_TIMEOUT);	/* its last TPDO was already on the bus */
	CHECK_EQ(co_master_node(&m, 0)->error_code, CO_ERR_PDO_TIMEOUT);
	run(&m, 21);
	CHECK_EQ(co_master_node(&m, 0)->error_code, CO_ERR_NMT_PREOP);
	run(&m, 100);
	CHECK_EQ(co_master_node(&m, 0)->error_code, CO_ERR_NMT_PREOP);
	CHECK_EQ(co_master_node(&m, 0)->nmt_lost, 1);
	CHECK_EQ(m.st.faults, 1);
	CHECK_EQ(m.st.pdo_timeouts, 1);
}

/* A second NMT master on the bus sends node 1 to pre-operational, then
 * node 2 to stopped: each axis faults in the next cycle. */
static void test_other_master(void)
{
	struct co_master m;
	int c, c2;

	bring_up(&m, 2);
	other_master_nmt(0x80, drv[0].id);
	c = cycles_to_fault(&m, 0, 100);
	CHECK_EQ(c, 1);
	CHECK_EQ(co_master_node(&m, 0)->error_code, CO_ERR_NMT_PREOP);
	CHECK_EQ(co_master_node(&m, 1)->fault, 0);
	other_master_nmt(0x02, drv[1].id);
	c2 = cycles_to_fault(&m, 1, 100);
	CHECK_EQ(c2, 1);
	CHECK_EQ(co_master_node(&m, 1)->error_code, CO_ERR_NMT_STOPPED);
	CHECK_EQ(co_master_node(&m, 1)->nmt_state, 4);
	CHECK_EQ(m.st.nmt_foreign, 2);
	printf("other master: pre-operational faulted after %d cycle(s), stopped after %d\n", c, c2);
	run(&m, 30);	/* the stopped node's heartbeats say 0x04 */
	CHECK_EQ(co_master_node(&m, 1)->error_code, CO_ERR_NMT_STOPPED);
	/* a start or a reset of another master is not a fault; a foreign
	 * NMT command that is not 2 bytes is malformed */
	{
		struct can_frame f;
		uint32_t bad = m.st.rx_bad, faults = m.st.faults;

		memset(&f, 0, sizeof(f));
		f.dlc = 3;
		co_master_rx(&m, &f);
		CHECK_EQ(m.st.rx_bad, bad + 1);
		f.dlc = 2;
		f.data[0] = 0x01;
		co_master_rx(&m, &f);
		CHECK_EQ(m.st.faults, faults);
	}
	resume(&m);
	c = cycles_to_enabled(&m, 100);
	CHECK(c > 0 && c < 20);
	CHECK_EQ(drv[0].nmt, 5);
	CHECK_EQ(drv[1].nmt, 5);
}

/* Cycles after the resume until node idx's NMT start is on the bus. */
static int cycles_to_nmt_start(struct co_master *m, uint32_t idx, int limit)
{
	unsigned starts = drv[idx].nmt_starts;

	for (int c = 1; c <= limit; c++) {
		enable_all(m, 1);
		run(m, 1);
		if (drv[idx].nmt_starts != starts)
			return c;
	}
	return -1;
}

/* The resume after another master stopped a node: the node's heartbeat
 * that was due just before it handled the NMT start still says stopped,
 * and it reaches the master after the node's first TPDO (a heartbeat
 * loses arbitration to the TPDOs of the same SYNC). That is not the node
 * leaving Operational again (before: the axis faulted again with 0xff05 at
 * once and for good, its TPDOs ignored; once in a loaded run on the
 * ZynqMP board). A node that is stopped again right after its start is
 * still seen: its TPDO falls silent, and its next heartbeat says why. */
static void test_stale_heartbeat_after_the_start(void)
{
	const uint8_t stopped = 0x04;
	struct co_master m;
	uint32_t left;
	int c;

	bring_up(&m, 2);
	other_master_nmt(0x02, drv[1].id);
	CHECK_EQ(cycles_to_fault(&m, 1, 100), 1);
	left = m.st.nmt_left;
	resume(&m);
	c = cycles_to_nmt_start(&m, 1, 100);
	CHECK(c > 0);
	q_push(0x700u + drv[1].id, 1, &stopped);	/* behind its TPDO */
	c = cycles_to_enabled(&m, 100);
	printf("stale heartbeat after the start: enabled after %d cycles, nmt_left %u -> %u\n", c,
	       (unsigned)left, (unsigned)m.st.nmt_left);
	CHECK(c > 0 && c < 20);
	CHECK_EQ(m.st.nmt_left, left);
	CHECK_EQ(co_master_node(&m, 1)->fault, 0);
	/* stopped again, on its own, after its first TPDO and before its
	 * heartbeat said Operational */
	other_master_nmt(0x02, drv[1].id);
	CHECK_EQ(cycles_to_fault(&m, 1, 100), 1);
	left = m.st.nmt_left;
	resume(&m);
	CHECK(cycles_to_nmt_start(&m, 1, 100) > 0);
	run(&m, 1);		/* its TPDO confirms the start */
	CHECK(co_master_node(&m, 1)->confirmed);
	CHECK(!co_master_node(&m, 1)->hb_confirmed);
	drv[1].nmt = 4;
	c = cycles_to_fault(&m, 1, 100);
	run(&m, (int)CFG.hb_producer_ms);	/* its heartbeat says why */
	printf("stopped right after its start: faulted after %d cycles, error 0x%04x\n", c,
	       (unsigned)co_master_node(&m, 1)->error_code);
	CHECK(c > 0 && c <= (int)CFG.hb_producer_ms + 1);
	CHECK_EQ(co_master_node(&m, 1)->error_code, CO_ERR_NMT_STOPPED);
	CHECK_EQ(m.st.nmt_left, left + 1);
}

/* The drive stays Operational and heart-beats, but its TPDO stops: the
 * axis faults in the PDO_TIMEOUT-th cycle without it; one missing TPDO
 * is not a fault (test_canopen_master.c test_pdo_missing). */
static void test_tpdo_silence(void)
{
	struct co_master m;
	int c;

	bring_up(&m, 2);
	drv[1].tpdo_mute = 1;
	c = cycles_to_fault(&m, 1, 100);
	printf("tpdo: silent drive faulted after %d cycles (%u cycles without its TPDO)\n", c,
	       (unsigned)PDO_TIMEOUT);
	CHECK_EQ(c, 1 + PDO_TIMEOUT);	/* its last TPDO was already on the bus */
	CHECK_EQ(co_master_node(&m, 1)->error_code, CO_ERR_PDO_TIMEOUT);
	CHECK_EQ(co_master_node(&m, 1)->pdo_silent, PDO_TIMEOUT);
	CHECK_EQ(co_master_node(&m, 0)->fault, 0);
	/* the heartbeat still says Operational: the code stays */
	run(&m, 40);
	CHECK_EQ(co_master_node(&m, 1)->error_code, CO_ERR_PDO_TIMEOUT);
	CHECK_EQ(m.st.hb_timeouts, 0);
	/* back: latched until acknowledged, then enabled */
	drv[1].tpdo_mute = 0;
	run(&m, 5);
	CHECK_EQ(co_master_node(&m, 1)->fault, 1);
	CHECK_EQ(co_master_node(&m, 1)->pdo_silent, 0);
	resume(&m);
	c = cycles_to_enabled(&m, 50);
	CHECK(c > 0 && c < 10);
}

/* NMT start lost on the bus (a bus short destroyed it): sent again after
 * START_TIMEOUT cycles; lost every time: a fault after START_RETRIES
 * retries. */
static void test_lost_nmt_start(void)
{
	struct co_master m;
	int c;

	setup(&m, 1);
	drv[0].drop_nmt_start = 1;
	c = cycles_to_enabled(&m, 300);
	printf("nmt start: one lost, operation enabled after %d cycles, %u start(s) sent again\n", c,
	       (unsigned)m.st.start_retries);
	CHECK(c > START_TIMEOUT && c < START_TIMEOUT + 40);
	CHECK_EQ(m.st.start_retries, 1);
	CHECK_EQ(drv[0].nmt_starts, 1);
	CHECK_EQ(co_master_node(&m, 0)->fault, 0);

	setup(&m, 1);
	drv[0].drop_nmt_start = 1000;
	enable_all(&m, 1);
	c = cycles_to_fault(&m, 0, 2000);
	printf("nmt start: all lost, fault 0x%04x after %d cycles\n", (unsigned)co_master_node(&m, 0)->error_code, c);
	CHECK(c > 0 && c < 30 + (START_RETRIES + 1) * START_TIMEOUT + 5);
	CHECK(c >= (START_RETRIES + 1) * START_TIMEOUT);
	CHECK_EQ(co_master_node(&m, 0)->error_code, CO_ERR_NMT_START);
	CHECK_EQ(co_master_node(&m, 0)->phase, CO_PH_FAILED);
	CHECK_EQ(m.st.start_retries, START_RETRIES);
	CHECK_EQ(drv[0].nmt, 127);
	/* the bus is back: the acknowledgement starts it over */
	drv[0].drop_nmt_start = 0;
	resume(&m);
	c = cycles_to_enabled(&m, 300);
	CHECK(c > 0);
}

/* PDO COB-IDs: bit 29 (a 29-bit identifier), bit 31 (not valid), bits
 * 11-28, another identifier: each refused at configuration with its
 * reason; the node never started. */
static void test_cob_id(uint32_t tpdo, uint32_t rpdo, enum co_cfg_reason why)
{
	struct co_master m;

	setup(&m, 1);
	drv[0].cob1800 = tpdo;
	drv[0].cob1400 = rpdo;
	enable_all(&m, 1);
	run(&m, 40);
	printf("cob-id 0x%08x / 0x%08x: %s, %s (reason: %s, 0x%04x:%02x = 0x%08x)\n", (unsigned)tpdo, (unsigned)rpdo,
	       co_phase_name((enum co_node_phase)co_master_node(&m, 0)->phase),
	       co_master_node(&m, 0)->fault ? "fault" : "no fault",
	       co_cfg_reason_name((enum co_cfg_reason)co_master_node(&m, 0)->cfg_reason),
	       (unsigned)co_master_node(&m, 0)->cfg_index, (unsigned)co_master_node(&m, 0)->cfg_sub,
	       (unsigned)co_master_node(&m, 0)->cfg_value);
	CHECK_EQ(co_master_node(&m, 0)->phase, CO_PH_FAILED);
	CHECK_EQ(co_master_node(&m, 0)->error_code, CO_ERR_PDO_COB_ID);
	CHECK_EQ(co_master_node(&m, 0)->cfg_reason, why);
	CHECK_EQ(co_master_node(&m, 0)->cfg_value, why == CO_CFG_COB_ID ? rpdo : tpdo);
	CHECK_EQ(co_master_node(&m, 0)->cfg_index, why == CO_CFG_COB_ID ? 0x1400 : 0x1800);
	CHECK_EQ(drv[0].nmt, 127);
	CHECK_EQ(m.st.rpdo_sent, 0);
}

/* A drive that needs `delay` SYNCs, bit 7 held, to leave Fault: one
 * acknowledgement enables it; the stale EMCY code does not come back. */
static void test_slow_fault_reset(int delay, int tx_full)
{
	struct co_master m;
	int c;

	bring_up(&m, 1);
	drv[0].reset_delay = delay;
	drive_fault(&drv[0], 0x8611);
	run(&m, 3);
	CHECK_EQ(co_master_node(&m, 0)->error_code, 0x8611);
	CHECK_EQ(co_master_node(&m, 0)->state402, CO402_FAULT);
	drv[0].cw_hist_n = 0;
	resume(&m);
	if (tx_full)
		tx_busy_left = 1;	/* the first reset word refused by the TX FIFO */
	c = cycles_to_enabled(&m, 200);
	printf("fault reset: drive needing %d cycle(s)%s: operation enabled %d cycles after one resume\n", delay,
	       tx_full ? ", TX FIFO full at the reset" : "", c);
	CHECK(c > delay && c <= delay + 6 + tx_full);
	CHECK_EQ(co_master_node(&m, 0)->error_code, 0);
	CHECK_EQ(co_master_node(&m, 0)->emcy_last, 0);
	CHECK_EQ(m.st.faults, 1);
	CHECK_EQ(drv[0].cw_hist[0], CO_CW_FAULT_RESET);
	CHECK_EQ(m.st.fault_resets, 1);
}

/* A drive that never leaves Fault: "fault reset refused by drive" after
 * RESET_TIMEOUT cycles, bit 7 dropped; willing again, the next
 * acknowledgement resets it with a new rising edge. */
static void test_fault_reset_refused(void)
{
	struct co_master m;
	int c;

	bring_up(&m, 1);
	drv[0].reset_delay = -1;
	drive_fault(&drv[0], 0x2310);
	run(&m, 3);
	resume(&m);
	run(&m, 1);
	CHECK_EQ(co_master_node(&m, 0)->fault, 0);
	c = cycles_to_fault(&m, 0, 500);
	printf("fault reset: refused by drive after %d cycles: error 0x%04x\n", c,
	       (unsigned)co_master_node(&m, 0)->error_code);
	CHECK(c >= RESET_TIMEOUT - 2 && c <= RESET_TIMEOUT + 2);
	CHECK_EQ(co_master_node(&m, 0)->error_code, CO_ERR_FAULT_RESET);
	CHECK_EQ(m.st.fault_reset_refused, 1);
	run(&m, 2);
	CHECK_EQ(co_master_node(&m, 0)->controlword & CO_CW_FAULT_RESET, 0);
	drv[0].reset_delay = 3;
	resume(&m);
	c = cycles_to_enabled(&m, 50);
	CHECK(c > 3 && c < 12);
}

int main(void)
{
	test_heartbeat_not_operational(0x7F, CO_ERR_NMT_PREOP);
	test_heartbeat_not_operational(0x04, CO_ERR_NMT_STOPPED);
	test_preop_between_heartbeats();
	test_other_master();
	test_stale_heartbeat_after_the_start();
	test_tpdo_silence();
	test_lost_nmt_start();
	test_cob_id(0x20000181u, 0x201u, CO_CFG_COB_29BIT);
	test_cob_id(0x80000181u, 0x201u, CO_CFG_COB_INVALID);
	test_cob_id(0x00000981u, 0x201u, CO_CFG_COB_BITS);
	test_cob_id(0x40000181u, 0x202u, CO_CFG_COB_ID);
	for (int d = 1; d <= 50; d += (d < 5 ? 1 : 15))
		test_slow_fault_reset(d, 0);
	test_slow_fault_reset(2, 1);
	test_fault_reset_refused();
	printf("canopen_faults: %d checks, %d failed\n", checks, failed);
	return failed ? 1 : 0;
}
