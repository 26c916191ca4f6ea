/* SPDX-License-Identifier: MIT */
/*
 * The bus and the scripted CiA 402 drives of the CANopen master's host
 * unit tests (co_testbus.h): an object dictionary answering expedited
 * SDOs, NMT, the 402 state machine on the controlword, a TPDO1 on every
 * SYNC, a heartbeat, EMCY on injected faults, and knobs to make a drive
 * misbehave.
 */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "co_testbus.h"

int failed, checks;

struct can_frame to_master[QMAX];
unsigned n_to_master;
int tx_busy_left;	/* refuse this many sends */
unsigned sent_log_n;
struct can_frame sent_log[SENT_LOG_MAX];

struct drive drv[ND];

void q_push(uint32_t id, uint8_t dlc, const uint8_t *data)
{
	struct can_frame *f;

	if (n_to_master >= QMAX)
		abort();
	f = &to_master[n_to_master++];
	memset(f, 0, sizeof(*f));
	f->id = id;
	f->dlc = dlc;
	if (data)
		memcpy(f->data, data, dlc);
}

void drive_reset(struct drive *d, uint8_t id)
{
	memset(d, 0, sizeof(*d));
	d->id = id;
	d->present = 1;
	d->boots = 1;
	d->nmt = 127;
	d->sw = 0x0040;	/* switch on disabled */
	d->map1a00[0] = 2;
	d->map1a00[1] = 0x60410010u;
	d->map1a00[2] = 0x60640020u;
	d->map1600[0] = 2;
	d->map1600[1] = 0x60400010u;
	d->map1600[2] = 0x607A0020u;
	d->cob1800 = 0x40000180u + id;
	d->cob1400 = 0x200u + id;
	d->tt1800 = 0xFE;
	d->tt1400 = 0xFE;
	d->hb_ms = 0;
	d->pos = 1000 * id;
}

static int od_read(struct drive *d, uint16_t idx, uint8_t sub, uint32_t *v, uint32_t *size)
{
	*size = 4;
	switch (idx) {
	case 0x6061: *v = (uint32_t)(uint8_t)d->mode_disp; *size = 1; return 0;
	case 0x6060: *v = (uint32_t)(uint8_t)d->mode; *size = 1; return 0;
	case 0x1A00: if (sub > 2) return -1; *v = d->map1a00[sub]; if (!sub) *size = 1; return 0;
	case 0x1600: if (sub > 2) return -1; *v = d->map1600[sub]; if (!sub) *size = 1; return 0;
	case 0x1800: if (sub == 1) { *v = d->cob1800; return 0; }
		if (sub == 2) { *v = d->tt1800; *size = 1; return 0; } return -1;
	case 0x1400: if (sub == 1) { *v = d->cob1400; return 0; }
		if (sub == 2) { *v = d->tt1400; *size = 1; return 0; } return -1;
	case 0x1017: *v = d->hb_ms; *size = 2; return 0;
	default: return -1;
	}
}

static int od_write(struct drive *d, uint16_t idx, uint8_t sub, uint32_t v)
{
	switch (idx) {
	case 0x6060: d->mode = (int8_t)v; d->mode_disp = (int8_t)v; return 0;
	case 0x1800: if (sub != 2) return -1; d->tt1800 = (uint8_t)v; return 0;
	case 0x1400: if (sub != 2) return -1; d->tt1400 = (uint8_t)v; return 0;
	case 0x1017: d->hb_ms = (uint16_t)v; return 0;
	default: return -1;
	}
}

static void sdo_answer(struct drive *d, const struct can_frame *f)
{
	uint8_t r[8] = { 0 };
	uint16_t idx = (uint16_t)(f->data[1] | f->data[2] << 8);
	uint8_t sub = f->data[3];
	uint32_t v = 0, size = 0;

	memcpy(&r[1], &f->data[1], 3);
	if (d->abort_index == idx) {
		r[0] = 0x80;
		r[4] = 0x00; r[5] = 0x00; r[6] = 0x02; r[7] = 0x06;	/* 0x06020000: no object */
	} else if (f->data[0] == 0x40) {
		if (od_read(d, idx, sub, &v, &size)) {
			r[0] = 0x80; r[7] = 0x06; r[6] = 0x02;
		} else {
			r[0] = (uint8_t)(0x43 | ((4 - size) << 2));
			for (uint32_t i = 0; i < size; i++)
				r[4 + i] = (uint8_t)(v >> (8 * i));
		}
	} else if ((f->data[0] & 0xE3) == 0x23) {
		size = 4 - ((f->data[0] >> 2) & 3);
		for (uint32_t i = 0; i < size; i++)
			v |= (uint32_t)f->data[4 + i] << (8 * i);
		if (od_write(d, idx, sub, v)) {
			r[0] = 0x80; r[7] = 0x06; r[6] = 0x01;	/* 0x06010000: unsupported access */
		} else {
			r[0] = 0x60;
		}
	} else {
		r[0] = 0x80; r[7] = 0x05; r[6] = 0x04; r[4] = 0x01;
	}
	q_push(0x580u + d->id, 8, r);
}

static void cw_record(struct drive *d, uint16_t cw)
{
	if (d->cw_hist_n && d->cw_hist[d->cw_hist_n - 1] == cw)
		return;
	if (d->cw_hist_n < 64)
		d->cw_hist[d->cw_hist_n++] = cw;
}

/* CiA 402 device state machine on one controlword. */
static void sm_apply(struct drive *d, uint16_t cw)
{
	uint16_t st = d->sw & 0x6F;
	int fault = (d->sw & 0x4F) == 0x08;

	cw_record(d, cw);
	if (fault) {
		if ((cw & 0x80) && !(d->cw & 0x80)) {	/* fault reset: its rising edge */
			if (d->reset_delay == 0)
				d->sw = 0x0040;	/* -> switch on disabled */
			else
				d->reset_count = d->reset_delay;
		} else if (!(cw & 0x80)) {
			d->reset_count = 0;	/* bit 7 dropped: this drive abandons the reset */
		}
		d->cw = cw;
		return;
	}
	d->cw = cw;
	if ((cw & 0x02) == 0) {	/* disable voltage */
		d->sw = 0x0040;
		return;
	}
	if ((cw & 0x87) == 0x06) {	/* shutdown */
		d->sw = 0x0021;
		return;
	}
	if ((cw & 0x8F) == 0x07) {	/* switch on / disable operation */
		if (st == 0x21 || st == 0x27 || st == 0x23)
			d->sw = 0x0023;
		return;
	}
	if ((cw & 0x8F) == 0x0F) {	/* enable operation */
		if (st == 0x23 || st == 0x27) {
			if (st == 0x23)
				d->target = d->pos;
			d->sw = 0x0027;
		}
		return;
	}
}

void drive_fault(struct drive *d, uint16_t code)
{
	uint8_t e[8] = { (uint8_t)code, (uint8_t)(code >> 8), 0x01, 0, 0, 0, 0, 0 };

	d->sw = 0x0008;
	q_push(0x80u + d->id, 8, e);
}

void drive_rx(struct drive *d, const struct can_frame *f)
{
	if (!d->present || d->hb_silent)
		return;
	if (f->id == 0x000 && f->dlc == 2 && (f->data[1] == d->id || f->data[1] == 0)) {
		if (f->data[0] == 0x01 && d->drop_nmt_start > 0) {
			d->drop_nmt_start--;	/* destroyed on the bus */
			return;
		}
		if (f->data[0] == 0x82 || f->data[0] == 0x81) {
			d->nmt = 127;
			if (d->boots) {
				uint8_t b = 0;

				q_push(0x700u + d->id, 1, &b);
			}
		} else if (f->data[0] == 0x01) {
			d->nmt = 5;
			d->nmt_starts++;
		} else if (f->data[0] == 0x02) {
			d->nmt = 4;
		} else if (f->data[0] == 0x80) {
			d->nmt = 127;
		}
		return;
	}
	if (f->id == 0x600u + d->id && d->nmt != 4) {
		if (f->dlc == 8)
			sdo_answer(d, f);
		return;
	}
	if (f->id == 0x200u + d->id && d->nmt == 5 && f->dlc == 6) {
		d->rpdo_cw = (uint16_t)(f->data[0] | f->data[1] << 8);
		d->rpdo_target = (int32_t)((uint32_t)f->data[2] | (uint32_t)f->data[3] << 8 |
					   (uint32_t)f->data[4] << 16 | (uint32_t)f->data[5] << 24);
		d->rpdo_new = 1;
		return;
	}
	if (f->id == 0x080 && f->dlc == 0 && d->nmt == 5) {
		uint8_t t[6];

		if ((d->sw & 0x4F) == 0x08 && d->reset_count > 0 && --d->reset_count == 0) {
			uint8_t z[8] = { 0 };

			d->sw = 0x0040;	/* the reset done: switch on disabled, EMCY "no error" */
			q_push(0x80u + d->id, 8, z);
		}
		if (d->rpdo_new) {
			d->rpdo_new = 0;
			sm_apply(d, d->rpdo_cw);
			if ((d->sw & 0x6F) == 0x27)
				d->target = d->rpdo_target;
		}
		if ((d->sw & 0x6F) == 0x27)
			d->pos += (d->target - d->pos) / 2;	/* a crisp servo */
		if (d->tpdo_mute)
			return;
		t[0] = (uint8_t)d->sw;
		t[1] = (uint8_t)(d->sw >> 8);
		for (int i = 0; i < 4; i++)
			t[2 + i] = (uint8_t)((uint32_t)d->pos >> (8 * i));
		q_push(0x180u + d->id, 6, t);
	}
}

void other_master_nmt(uint8_t cs, uint8_t node)
{
	struct can_frame f;

	memset(&f, 0, sizeof(f));
	f.dlc = 2;
	f.data[0] = cs;
	f.data[1] = node;
	for (int i = 0; i < ND; i++)
		drive_rx(&drv[i], &f);
	q_push(0x000, 2, f.data);
}

int fake_send(void *ctx, const struct can_frame *f)
{
	(void)ctx;
	if (tx_busy_left > 0) {
		tx_busy_left--;
		return 1;
	}
	CHECK(f->dlc <= 8);
	CHECK(f->id <= 0x7FF);
	if (sent_log_n < sizeof(sent_log) / sizeof(sent_log[0]))
		sent_log[sent_log_n++] = *f;
	for (int i = 0; i < ND; i++)
		drive_rx(&drv[i], f);
	return 0;
}

/* Once per cycle for the drives (1 ms): heartbeats. */
void drives_tick(void)
{
	for (int i = 0; i < ND; i++) {
		struct drive *d = &drv[i];
		uint8_t s = (uint8_t)d->nmt;

		d->cycle++;
		if (!d->present || d->hb_silent || !d->hb_ms)
			continue;
		if (d->cycle % d->hb_ms == 0)
			q_push(0x700u + d->id, 1, &s);
	}
}

void deliver(struct co_master *m)
{
	/* answers to this cycle's frames arrive before the next cycle */
	unsigned n = n_to_master;
	struct can_frame tmp[QMAX];

	memcpy(tmp, to_master, n * sizeof(tmp[0]));
	n_to_master = 0;
	for (unsigned i = 0; i < n; i++)
		co_master_rx(m, &tmp[i]);
}

void run(struct co_master *m, int cycles)
{
	for (int c = 0; c < cycles; c++) {
		deliver(m);
		co_master_cycle(m);
		drives_tick();
	}
}

const struct co_config CFG = {
	.period_us = 1000, .hb_producer_ms = 10, .hb_consumer_ms = 30, .sdo_timeout_ms = 20,
	.boot_timeout_ms = 50, .boot_retries = 2, .sdo_retries = 1,
};

void setup(struct co_master *m, int n)
{
	static const uint8_t ids[ND] = { 1, 2, 5 };

	n_to_master = 0;
	tx_busy_left = 0;
	sent_log_n = 0;
	for (int i = 0; i < ND; i++)
		drive_reset(&drv[i], ids[i]);
	CHECK_EQ(co_master_init(m, fake_send, NULL, &CFG, ids, (uint32_t)n), 0);
	co_master_start(m);
}

void enable_all(struct co_master *m, int on)
{
	for (uint32_t i = 0; i < m->n_nodes; i++)
		co_master_set(m, i, on, drv[i].pos);
}

void bring_up(struct co_master *m, int n)
{
	setup(m, n);
	for (int c = 0; c < 60; c++) {
		enable_all(m, 1);
		run(m, 1);
	}
	for (int i = 0; i < n; i++)
		CHECK_EQ(co_master_node(m, (uint32_t)i)->state402, CO402_OPERATION_ENABLED);
}
