/* SPDX-License-Identifier: MIT */
/*
 * Host unit test of the CANopen master (rpu_app/src/canopen_master.c,
 * canopen_config.c, canopen_drive.c), built with
 * -fsanitize=address,undefined (test_rpu_canopen_host.py), against the
 * scripted drives of co_testbus.c: start-up, configuration, enable
 * sequence, EMCY and heartbeat faults, bus off, TX full, bounds, fuzz.
 * The supervision of issue 33 is test_canopen_faults.c.
 */
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "co_testbus.h"

static void test_init_checks(void)
{
	struct co_master m;
	uint8_t bad0[] = { 0 }, bad128[] = { 128 }, dup[] = { 3, 3 };
	uint8_t many[CO_MAX_NODES + 1];

	for (unsigned i = 0; i < sizeof(many); i++)
		many[i] = (uint8_t)(i + 1);
	CHECK(co_master_init(&m, fake_send, NULL, &CFG, bad0, 1) != 0);
	CHECK(co_master_init(&m, fake_send, NULL, &CFG, bad128, 1) != 0);
	CHECK(co_master_init(&m, fake_send, NULL, &CFG, dup, 2) != 0);
	CHECK(co_master_init(&m, fake_send, NULL, &CFG, many, CO_MAX_NODES + 1) != 0);
	CHECK(co_master_init(&m, NULL, NULL, &CFG, many, 1) != 0);
	CHECK(co_master_node(&m, 0) == NULL);
	CHECK_EQ(co_402_decode(0x0237), CO402_OPERATION_ENABLED);
	CHECK_EQ(co_402_decode(0x0250), CO402_SWITCH_ON_DISABLED);
	CHECK_EQ(co_402_decode(0x0231), CO402_READY_TO_SWITCH_ON);
	CHECK_EQ(co_402_decode(0x0233), CO402_SWITCHED_ON);
	CHECK_EQ(co_402_decode(0x0218), CO402_FAULT);
	CHECK_EQ(co_402_decode(0x021F), CO402_FAULT_REACTION_ACTIVE);
	CHECK_EQ(co_402_decode(0x0217), CO402_QUICK_STOP_ACTIVE);
	CHECK_EQ(co_402_decode(0x0000), CO402_NOT_READY);
	CHECK(strcmp(co_402_name(CO402_OPERATION_ENABLED), "operation enabled") == 0);
	CHECK(strcmp(co_phase_name(CO_PH_FAILED), "failed") == 0);
}

/* Start-up to operation enabled, the configuration written, the PDOs. */
static void test_enable_sequence(void)
{
	struct co_master m;
	struct co_stats st;
	int cyc_to_op = -1;

	setup(&m, 2);
	for (int c = 0; c < 200 && cyc_to_op < 0; c++) {
		enable_all(&m, 1);
		run(&m, 1);
		if (co_master_node(&m, 0)->state402 == CO402_OPERATION_ENABLED &&
		    co_master_node(&m, 1)->state402 == CO402_OPERATION_ENABLED)
			cyc_to_op = c + 1;
	}
	printf("enable: both nodes in operation enabled after %d cycles\n", cyc_to_op);
	CHECK(cyc_to_op > 0 && cyc_to_op < 40);
	for (int i = 0; i < 2; i++) {
		const struct co_node *n = co_master_node(&m, (uint32_t)i);

		CHECK_EQ(drv[i].mode, 8);
		CHECK_EQ(drv[i].tt1800, 1);
		CHECK_EQ(drv[i].tt1400, 1);
		CHECK_EQ(drv[i].hb_ms, 10);
		CHECK_EQ(drv[i].nmt, 5);
		CHECK_EQ(n->phase, CO_PH_OPERATIONAL);
		CHECK_EQ(n->fault, 0);
		/* shutdown -> switch on -> enable operation, nothing else */
		CHECK(drv[i].cw_hist_n >= 3);
		CHECK_EQ(drv[i].cw_hist[0], CO_CW_SHUTDOWN);
		CHECK_EQ(drv[i].cw_hist[1], CO_CW_SWITCH_ON);
		CHECK_EQ(drv[i].cw_hist[2], CO_CW_ENABLE_OPERATION);
		CHECK_EQ(drv[i].cw_hist_n, 3);
	}
	/* node 5 was never configured: not ours */
	CHECK_EQ(drv[2].mode, 0);

	/* the target goes through; the position follows */
	for (int c = 0; c < 50; c++) {
		co_master_set(&m, 0, 1, 12345);
		co_master_set(&m, 1, 1, -777);
		run(&m, 1);
	}
	CHECK_EQ(co_master_node(&m, 0)->target_sent, 12345);
	CHECK_EQ(drv[0].target, 12345);
	CHECK_EQ(drv[1].target, -777);
	CHECK(co_master_node(&m, 0)->pos_actual > 12300);
	CHECK(co_master_node(&m, 1)->pos_actual < -700);
	co_master_stats(&m, &st);
	CHECK_EQ(st.sync_sent, st.cycles);
	CHECK_EQ(st.sync_missed, 0);
	CHECK_EQ(st.pdo_missing, 0);
	CHECK_EQ(st.faults, 0);
	CHECK_EQ(st.hb_timeouts, 0);
	CHECK_EQ(st.nodes_operational, 2);
	CHECK(st.hb_rx > 0);
	CHECK_EQ(st.sdo_ok, 2 * 13);
	printf("enable: cycles=%u sync=%u rpdo=%u tpdo=%u sdo_ok=%u hb=%u\n", (unsigned)st.cycles,
	       (unsigned)st.sync_sent, (unsigned)st.rpdo_sent, (unsigned)st.tpdo_rx, (unsigned)st.sdo_ok,
	       (unsigned)st.hb_rx);

	/* disable: shutdown, the drive leaves operation enabled */
	enable_all(&m, 0);
	run(&m, 3);
	CHECK_EQ(co_master_node(&m, 0)->controlword, CO_CW_SHUTDOWN);
	CHECK_EQ(co_master_node(&m, 0)->state402, CO402_READY_TO_SWITCH_ON);
}

/* Until the drive runs enabled, the target sent is its own position. */
static void test_no_jump_on_enable(void)
{
	struct co_master m;

	setup(&m, 1);
	for (int c = 0; c < 60; c++) {
		co_master_set(&m, 0, c >= 30, 99999);
		run(&m, 1);
		if (co_master_node(&m, 0)->phase == CO_PH_OPERATIONAL &&
		    co_master_node(&m, 0)->state402 != CO402_OPERATION_ENABLED &&
		    co_master_node(&m, 0)->pos_valid)
			CHECK_EQ(co_master_node(&m, 0)->target_sent, co_master_node(&m, 0)->pos_actual);
	}
	CHECK_EQ(co_master_node(&m, 0)->state402, CO402_OPERATION_ENABLED);
	CHECK_EQ(drv[0].target, 99999);
}

static void test_wrong_mapping_and_abort(void)
{
	struct co_master m;

	setup(&m, 2);
	drv[0].map1a00[2] = 0x606C0020u;	/* velocity instead of position */
	drv[1].abort_index = 0x6060;
	enable_all(&m, 1);
	run(&m, 60);
	CHECK_EQ(co_master_node(&m, 0)->phase, CO_PH_FAILED);
	CHECK_EQ(co_master_node(&m, 0)->fault, 1);
	CHECK_EQ(co_master_node(&m, 0)->error_code, CO_ERR_CONFIG);
	CHECK_EQ(co_master_node(&m, 1)->phase, CO_PH_FAILED);
	CHECK_EQ(co_master_node(&m, 1)->sdo_abort, 0x06020000u);
	CHECK_EQ(m.st.sdo_abort, 1);
	CHECK_EQ(drv[0].nmt, 127);	/* never started */
	/* a failed node gets no PDO; SYNC keeps going */
	CHECK_EQ(m.st.rpdo_sent, 0);
	CHECK_EQ(m.st.sync_sent, 60);

	/* fixed: the enable request off and on again is no acknowledgement */
	drv[0].map1a00[2] = 0x60640020u;
	enable_all(&m, 0);
	run(&m, 1);
	enable_all(&m, 1);
	run(&m, 40);
	CHECK_EQ(co_master_node(&m, 0)->phase, CO_PH_FAILED);
	CHECK_EQ(co_master_node(&m, 0)->error_code, CO_ERR_CONFIG);
	/* the operator's acknowledgement retries the start-up */
	co_master_acknowledge(&m, 0);
	run(&m, 40);
	CHECK_EQ(co_master_node(&m, 0)->phase, CO_PH_OPERATIONAL);
	CHECK_EQ(co_master_node(&m, 0)->state402, CO402_OPERATION_ENABLED);
	CHECK_EQ(co_master_node(&m, 0)->fault, 0);
	CHECK_EQ(co_master_node(&m, 1)->phase, CO_PH_FAILED);
}

static void test_boot_timeout(void)
{
	struct co_master m;

	setup(&m, 1);
	drv[0].boots = 0;
	run(&m, 50 * 3 + 5);
	CHECK_EQ(co_master_node(&m, 0)->phase, CO_PH_FAILED);
	CHECK_EQ(co_master_node(&m, 0)->error_code, CO_ERR_BOOT_TIMEOUT);
	CHECK_EQ(m.st.nmt_sent, 3);	/* the first reset and 2 retries */
}

static void test_sdo_timeout(void)
{
	struct co_master m;

	setup(&m, 1);
	enable_all(&m, 1);
	run(&m, 3);	/* boot-up answered */
	CHECK_EQ(co_master_node(&m, 0)->phase, CO_PH_CONFIG);
	drv[0].present = 0;	/* gone mid-configuration */
	run(&m, 20 * 2 + 5);
	CHECK_EQ(co_master_node(&m, 0)->phase, CO_PH_FAILED);
	CHECK_EQ(m.st.sdo_timeout, 2);
	CHECK_EQ(co_master_node(&m, 0)->error_code, CO_ERR_CONFIG);
}

static void test_emcy_fault_and_reset(void)
{
	struct co_master m;
	int detect = -1;

	bring_up(&m, 2);
	drive_fault(&drv[1], 0x8611);	/* following error */
	for (int c = 0; c < 10 && detect < 0; c++) {
		run(&m, 1);
		if (co_master_node(&m, 1)->fault)
			detect = c + 1;
	}
	CHECK_EQ(detect, 1);
	CHECK_EQ(co_master_node(&m, 1)->error_code, 0x8611);
	CHECK_EQ(co_master_node(&m, 1)->emcy_last, 0x8611);
	CHECK_EQ(m.st.emcy, 1);
	run(&m, 2);
	CHECK_EQ(co_master_node(&m, 1)->state402, CO402_FAULT);
	CHECK_EQ(co_master_node(&m, 0)->fault, 0);
	CHECK_EQ(co_master_node(&m, 0)->state402, CO402_OPERATION_ENABLED);
	/* the enable request held: still faulted, no reset sent */
	run(&m, 5);
	CHECK_EQ(co_master_node(&m, 1)->fault, 1);
	CHECK_EQ(co_master_node(&m, 1)->state402, CO402_FAULT);
	/* the enable request off and on again (Linux does that when a
	 * program ends in fault): no acknowledgement, no reset */
	co_master_set(&m, 1, 0, drv[1].pos);
	run(&m, 1);
	co_master_set(&m, 1, 1, drv[1].pos);
	run(&m, 5);
	CHECK_EQ(co_master_node(&m, 1)->fault, 1);
	CHECK_EQ(co_master_node(&m, 1)->error_code, 0x8611);
	CHECK_EQ(co_master_node(&m, 1)->state402, CO402_FAULT);
	/* the acknowledgement: fault reset, then the sequence again */
	drv[1].cw_hist_n = 0;
	co_master_acknowledge(&m, 1);
	run(&m, 8);
	CHECK_EQ(co_master_node(&m, 1)->fault, 0);
	CHECK_EQ(co_master_node(&m, 1)->error_code, 0);
	CHECK_EQ(co_master_node(&m, 1)->state402, CO402_OPERATION_ENABLED);
	CHECK(drv[1].cw_hist_n >= 2);
	CHECK_EQ(drv[1].cw_hist[0], CO_CW_FAULT_RESET);

	/* a drive in fault without an EMCY: a generic drive fault */
	drv[0].sw = 0x0008;
	run(&m, 3);
	CHECK_EQ(co_master_node(&m, 0)->fault, 1);
	CHECK_EQ(co_master_node(&m, 0)->error_code, 0x1000);
	/* EMCY "no error" does not fault */
	{
		uint8_t z[8] = { 0 };

		q_push(0x80u + drv[1].id, 8, z);
		run(&m, 2);
		CHECK_EQ(co_master_node(&m, 1)->fault, 0);
	}
}

static void test_heartbeat_consumer(void)
{
	struct co_master m;
	int detect = -1;

	int named = -1;

	bring_up(&m, 2);
	drv[0].hb_silent = 1;	/* drops off the bus: no TPDO, no heartbeat */
	for (int c = 0; c < 100 && named < 0; c++) {
		run(&m, 1);
		if (co_master_node(&m, 0)->fault && detect < 0) {
			detect = c + 1;
			CHECK_EQ(co_master_node(&m, 0)->error_code, CO_ERR_PDO_TIMEOUT);
		}
		if (co_master_node(&m, 0)->error_code == CO_ERR_HEARTBEAT)
			named = c + 1;
	}
	/* its TPDO was already on the bus: the first SYNC it misses is in
	 * cycle 1, the second cycle without its answer is cycle 3; the
	 * heartbeat consumer then names the cause (the code is refined) */
	printf("heartbeat: silent node faulted after %d cycles (no TPDO for %u cycles), named silent after %d "
	       "(consumer %u ms, producer %u ms)\n", detect, (unsigned)CO_DEFAULT_PDO_TIMEOUT_CYCLES, named,
	       (unsigned)CFG.hb_consumer_ms, (unsigned)CFG.hb_producer_ms);
	CHECK_EQ(detect, 1 + CO_DEFAULT_PDO_TIMEOUT_CYCLES);
	CHECK(named > 0 && named <= CFG.hb_consumer_ms + 1);
	CHECK(named >= CFG.hb_consumer_ms - CFG.hb_producer_ms);
	CHECK_EQ(co_master_node(&m, 0)->error_code, CO_ERR_HEARTBEAT);
	CHECK_EQ(m.st.hb_timeouts, 1);
	CHECK_EQ(m.st.pdo_timeouts, 1);
	CHECK(m.st.pdo_missing >= (uint32_t)named - 1);
	CHECK_EQ(co_master_node(&m, 1)->fault, 0);
	/* the consumer does not fire again while the node stays silent */
	run(&m, 100);
	CHECK_EQ(m.st.hb_timeouts, 1);
	CHECK_EQ(m.st.faults, 1);

	/* it comes back after a power cycle: boot-up, reconfiguration */
	drv[0].hb_silent = 0;
	drv[0].nmt = 127;
	drv[0].sw = 0x0040;
	{
		uint8_t b = 0;

		q_push(0x700u + drv[0].id, 1, &b);
	}
	run(&m, 30);
	CHECK_EQ(co_master_node(&m, 0)->phase, CO_PH_OPERATIONAL);
	CHECK_EQ(co_master_node(&m, 0)->fault, 1);	/* latched until acknowledged */
	co_master_set(&m, 0, 0, 0);
	run(&m, 1);
	co_master_set(&m, 0, 1, drv[0].pos);
	run(&m, 6);
	CHECK_EQ(co_master_node(&m, 0)->fault, 1);	/* the enable again is none */
	co_master_acknowledge(&m, 0);
	run(&m, 6);
	CHECK_EQ(co_master_node(&m, 0)->fault, 0);
	CHECK_EQ(co_master_node(&m, 0)->state402, CO402_OPERATION_ENABLED);
}

static void test_restart_while_operational(void)
{
	struct co_master m;
	uint8_t b = 0;

	bring_up(&m, 1);
	drv[0].nmt = 127;
	drv[0].sw = 0x0040;
	q_push(0x700u + drv[0].id, 1, &b);
	run(&m, 1);
	CHECK_EQ(co_master_node(&m, 0)->fault, 1);
	CHECK_EQ(co_master_node(&m, 0)->error_code, CO_ERR_RESTARTED);
	CHECK_EQ(co_master_node(&m, 0)->phase, CO_PH_CONFIG);
	run(&m, 30);
	CHECK_EQ(co_master_node(&m, 0)->phase, CO_PH_OPERATIONAL);
}

static void test_tx_full(void)
{
	struct co_master m;

	bring_up(&m, 2);
	m.st = (struct co_stats){ 0 };
	tx_busy_left = 3;	/* 2 RPDOs and the SYNC of one cycle refused */
	run(&m, 1);
	CHECK_EQ(m.st.sync_missed, 1);
	CHECK_EQ(m.st.rpdo_missed, 2);
	CHECK_EQ(m.st.tx_busy, 3);
	run(&m, 1);
	/* no SYNC went out: no TPDO came, and that is what "missing" counts */
	CHECK_EQ(m.st.pdo_missing, 0);
	run(&m, 5);
	CHECK_EQ(m.st.sync_missed, 1);
	CHECK_EQ(m.st.sync_sent, 6);
	CHECK_EQ(co_master_node(&m, 0)->state402, CO402_OPERATION_ENABLED);

	/* bus off: every operational axis faults with its code */
	co_master_bus_off(&m);
	CHECK_EQ(m.st.bus_off, 1);
	CHECK_EQ(co_master_node(&m, 0)->error_code, CO_ERR_BUS_OFF);
	CHECK_EQ(co_master_node(&m, 1)->error_code, CO_ERR_BUS_OFF);
	/* latched while the axes keep asking for enable; the drives, not in
	 * Fault themselves, are only shut down */
	run(&m, 5);
	CHECK_EQ(co_master_node(&m, 0)->fault, 1);
	CHECK_EQ(co_master_node(&m, 1)->error_code, CO_ERR_BUS_OFF);
	CHECK_EQ(co_master_node(&m, 0)->state402, CO402_READY_TO_SWITCH_ON);
	/* the operator's acknowledgement (resume) with enable held: a new
	 * enable request, the fault cleared, the drives enabled again */
	co_master_acknowledge(&m, 0);
	co_master_acknowledge(&m, 1);
	co_master_acknowledge(&m, 7);	/* no such node: nothing */
	run(&m, 8);
	for (uint32_t i = 0; i < 2; i++) {
		CHECK_EQ(co_master_node(&m, i)->fault, 0);
		CHECK_EQ(co_master_node(&m, i)->error_code, 0);
		CHECK_EQ(co_master_node(&m, i)->state402, CO402_OPERATION_ENABLED);
	}
}

static void test_pdo_missing(void)
{
	struct co_master m;

	bring_up(&m, 2);
	m.st = (struct co_stats){ 0 };
	run(&m, 1);
	n_to_master = 0;	/* the TPDOs of one SYNC lost */
	run(&m, 1);
	CHECK_EQ(m.st.pdo_missing, 2);
	CHECK_EQ(m.st.pdo_missing_last, 2);
	CHECK_EQ(m.st.pdo_missing_max, 2);
	run(&m, 1);
	CHECK_EQ(m.st.pdo_missing_last, 0);
	CHECK_EQ(m.st.pdo_missing, 2);
}

/* Malformed and foreign frames: counted, never trusted. */
static void test_bounds(void)
{
	struct co_master m;
	struct can_frame f;
	uint32_t bad0;

	bring_up(&m, 2);
	bad0 = m.st.rx_bad;
	memset(&f, 0, sizeof(f));
	f.id = 0x181; f.dlc = 9;
	co_master_rx(&m, &f);			/* dlc > 8 */
	f.dlc = 255;
	co_master_rx(&m, &f);
	f.id = 0x181; f.dlc = 5;
	co_master_rx(&m, &f);			/* TPDO too short */
	f.id = 0x800; f.dlc = 0;
	co_master_rx(&m, &f);			/* id over 11 bits */
	f.id = 0xFFFFFFFFu;
	co_master_rx(&m, &f);
	f.id = 0x581; f.dlc = 7;
	co_master_rx(&m, &f);			/* SDO not 8 bytes */
	f.id = 0x081; f.dlc = 2;
	co_master_rx(&m, &f);			/* EMCY too short */
	f.id = 0x701; f.dlc = 0;
	co_master_rx(&m, &f);			/* heartbeat without a state */
	f.id = 0x181; f.dlc = 6; f.rtr = 1;
	co_master_rx(&m, &f);			/* remote frame */
	CHECK_EQ(m.st.rx_bad - bad0, 9);
	CHECK_EQ(co_master_node(&m, 0)->fault, 0);
	CHECK_EQ(co_master_node(&m, 0)->state402, CO402_OPERATION_ENABLED);

	memset(&f, 0, sizeof(f));
	f.id = 0x185; f.dlc = 6;		/* node 5: on the bus, not ours */
	co_master_rx(&m, &f);
	f.id = 0x17F; f.dlc = 8;		/* node 127, EMCY range */
	co_master_rx(&m, &f);
	f.id = 0x000; f.dlc = 2;		/* NMT from another master */
	co_master_rx(&m, &f);
	f.id = 0x601; f.dlc = 8;		/* an SDO request to node 1 */
	co_master_rx(&m, &f);
	f.id = 0x581; f.dlc = 8;		/* an SDO answer nobody asked for */
	co_master_rx(&m, &f);
	CHECK_EQ(co_master_node(&m, 0)->fault, 0);
	CHECK_EQ(m.st.faults, 0);
	co_master_set(&m, 99, 1, 0);		/* index out of range: ignored */
	CHECK(co_master_node(&m, 2) == NULL);

	/* an SDO answer for another index during configuration */
	setup(&m, 1);
	run(&m, 3);
	CHECK_EQ(co_master_node(&m, 0)->phase, CO_PH_CONFIG);
	memset(&f, 0, sizeof(f));
	f.id = 0x581; f.dlc = 8; f.data[0] = 0x60; f.data[1] = 0x34; f.data[2] = 0x12;
	co_master_rx(&m, &f);
	CHECK_EQ(m.st.sdo_bad, 1);
	CHECK_EQ(co_master_node(&m, 0)->phase, CO_PH_CONFIG);
	/* a segmented upload answer: refused */
	n_to_master = 0;
	while (co_master_node(&m, 0)->step != 1 || !co_master_node(&m, 0)->sdo_busy)
		run(&m, 1);
	n_to_master = 0;
	memset(&f, 0, sizeof(f));
	f.id = 0x581; f.dlc = 8; f.data[0] = 0x41; f.data[1] = 0x61; f.data[2] = 0x60;
	f.data[4] = 200;
	co_master_rx(&m, &f);
	CHECK_EQ(co_master_node(&m, 0)->phase, CO_PH_FAILED);
}

/* Random frames into a running master: the sanitizers watch. */
static void test_fuzz(void)
{
	struct co_master m;
	uint32_t seed = 12345;

	bring_up(&m, 2);
	for (int i = 0; i < 60000; i++) {
		struct can_frame f;

		seed = seed * 1103515245u + 12345u;
		f.id = (seed >> 8) & 0xFFFu;
		f.dlc = (uint8_t)((seed >> 20) & 0xF);
		f.rtr = (uint8_t)((seed >> 3) & 1u) & (uint8_t)((seed >> 5) & 1u);
		for (int b = 0; b < 8; b++) {
			seed = seed * 1103515245u + 12345u;
			f.data[b] = (uint8_t)(seed >> 16);
		}
		if (i % 4 == 0)
			f.id = 0x580u + (f.id & 3u);	/* aim at the SDO path */
		co_master_rx(&m, &f);
		if (i % 97 == 0) {
			enable_all(&m, (i / 97) & 1);
			run(&m, 1);
		}
	}
	printf("fuzz: rx=%u bad=%u ignored=%u faults=%u\n", (unsigned)m.st.rx_frames, (unsigned)m.st.rx_bad,
	       (unsigned)m.st.rx_ignored, (unsigned)m.st.faults);
	CHECK(m.st.rx_bad > 0);
}

/* The master's time stamp: every stamp_ms, the first frame of its cycle,
 * 0x1013's microseconds little-endian on PDO 0x1FF; node id 127 is the
 * master's while stamps are on; a refused send is not counted. */
static void test_time_stamp(void)
{
	struct co_config cfg = CFG;
	struct co_master m;
	uint8_t ids[] = { 1, 2 }, id127[] = { 127 };
	unsigned stamps = 0;

	cfg.stamp_ms = 5;
	CHECK(co_master_init(&m, fake_send, NULL, &cfg, id127, 1) != 0);
	CHECK_EQ(co_master_init(&m, fake_send, NULL, &CFG, id127, 1), 0);	/* stamps off */
	CHECK(!co_master_stamp_due(&m));
	CHECK_EQ(co_master_init(&m, fake_send, NULL, &cfg, ids, 2), 0);
	n_to_master = 0;
	tx_busy_left = 0;
	for (int i = 0; i < ND; i++)
		drive_reset(&drv[i], (uint8_t)(i + 1));
	co_master_start(&m);
	for (uint32_t c = 0; c < 12u; c++) {
		unsigned first = sent_log_n;

		if (co_master_stamp_due(&m)) {
			CHECK_EQ(c % 5u, 0);
			co_master_time_stamp(&m, 0x12345670u + c);
			CHECK(sent_log_n == first + 1u);
			CHECK_EQ(sent_log[first].id, CO_COB_TIME_STAMP);
			CHECK_EQ(sent_log[first].dlc, 4);
			CHECK_EQ(sent_log[first].data[0], 0x70u + c);
			CHECK_EQ(sent_log[first].data[3], 0x12);
			stamps++;
		}
		co_master_cycle(&m);
		deliver(&m);
		drives_tick();
	}
	CHECK_EQ(stamps, 3);
	CHECK_EQ(m.st.stamps_sent, 3);
	tx_busy_left = 1;
	co_master_time_stamp(&m, 1);
	CHECK_EQ(m.st.stamps_sent, 3);
	CHECK_EQ(m.st.tx_busy, 1);
}

int main(void)
{
	test_init_checks();
	test_time_stamp();
	test_enable_sequence();
	test_no_jump_on_enable();
	test_wrong_mapping_and_abort();
	test_boot_timeout();
	test_sdo_timeout();
	test_emcy_fault_and_reset();
	test_heartbeat_consumer();
	test_restart_while_operational();
	test_tx_full();
	test_pdo_missing();
	test_bounds();
	test_fuzz();
	printf("canopen_master: %d checks, %d failed\n", checks, failed);
	return failed ? 1 : 0;
}
