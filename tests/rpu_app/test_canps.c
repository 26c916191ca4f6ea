/* SPDX-License-Identifier: MIT */
/*
 * Host unit test of rpu_app/src/canps.c (built with -DCANPS_HOST_TEST and
 * -fsanitize=address,undefined by test_rpu_canopen_host.py): the driver's
 * register accesses go to a small simulated CANPS (the behaviour of
 * QEMU's xlnx-zynqmp-can with our patches: SRR/SR modes, TX on the DW2
 * write, the RX FIFO popped by the ID read, RXNEMP re-raised while frames
 * remain, ICR clearing, ESR write-1-to-clear).
 */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "canps.h"

static int failed, checks;

#define CHECK(c) do { checks++; if (!(c)) { failed++; \
	fprintf(stderr, "%s:%d: CHECK failed: %s\n", __FILE__, __LINE__, #c); } } while (0)
#define CHECK_EQ(a, b) do { long long a_ = (long long)(a), b_ = (long long)(b); checks++; \
	if (a_ != b_) { failed++; fprintf(stderr, "%s:%d: %s == %lld (0x%llx), expected %s == %lld (0x%llx)\n", \
	__FILE__, __LINE__, #a, a_, (unsigned long long)a_, #b, b_, (unsigned long long)b_); } } while (0)

#define BASE 0xE0008000u

/* ---- the simulated controller -------------------------------------- */

static uint32_t reg[0x84 / 4];
static uint32_t rxq[256][4];
static unsigned rx_head, rx_n;
static uint32_t txw[4];
static unsigned txw_n;
static uint32_t sent[256][4];
static unsigned n_sent;
static int tx_full;		/* TX FIFO reported full */
static int never_config;	/* reset never reaches configuration mode */
static unsigned writes_srr;

static void update_isr(void)
{
	if (rx_n)
		reg[CANPS_ISR / 4] |= CANPS_IXR_RXNEMP;
}

static void rx_push(uint32_t idr, uint32_t dlc, uint32_t dw1, uint32_t dw2)
{
	if (rx_n >= 256)
		abort();
	unsigned i = (rx_head + rx_n++) % 256;

	rxq[i][0] = idr;
	rxq[i][1] = dlc << 28;
	rxq[i][2] = dw1;
	rxq[i][3] = dw2;
	reg[CANPS_ISR / 4] |= CANPS_IXR_RXOK;
	update_isr();
}

uint32_t canps_test_rd(uintptr_t a)
{
	uint32_t off = (uint32_t)(a - BASE);

	if (a < BASE || off >= sizeof(reg) || off % 4)
		abort();
	if (off == CANPS_SR)
		return reg[off / 4] | (tx_full ? CANPS_SR_TXFLL : 0u);
	if (off == CANPS_RXFIFO_ID) {
		if (!rx_n) {
			reg[CANPS_ISR / 4] |= CANPS_IXR_RXUFLW;
			return reg[off / 4];
		}
		for (int w = 0; w < 4; w++)
			reg[(CANPS_RXFIFO_ID / 4) + (unsigned)w] = rxq[rx_head][w];
		rx_head = (rx_head + 1) % 256;
		rx_n--;
		update_isr();
	}
	return reg[off / 4];
}

void canps_test_wr(uintptr_t a, uint32_t v)
{
	uint32_t off = (uint32_t)(a - BASE);

	if (a < BASE || off >= sizeof(reg) || off % 4)
		abort();
	switch (off) {
	case CANPS_SRR:
		writes_srr++;
		if (v & CANPS_SRR_SRST) {
			memset(reg, 0, sizeof(reg));
			rx_n = 0;
			reg[CANPS_ISR / 4] = 0x6000;
		}
		reg[CANPS_SRR / 4] = v & CANPS_SRR_CEN;
		if (v & CANPS_SRR_CEN)
			reg[CANPS_SR / 4] = CANPS_SR_NORMAL | (CANPS_ESTAT_ACTIVE << CANPS_SR_ESTAT_SHIFT);
		else
			reg[CANPS_SR / 4] = never_config ? 0u : CANPS_SR_CONFIG;
		return;
	case CANPS_ICR:
		reg[CANPS_ISR / 4] &= ~v;
		update_isr();
		return;
	case CANPS_ESR:
		reg[CANPS_ESR / 4] &= ~v;
		return;
	case CANPS_ISR:
	case CANPS_SR:
	case CANPS_ECR:
		return;	/* read-only */
	case CANPS_TXFIFO_ID:
	case CANPS_TXFIFO_DLC:
	case CANPS_TXFIFO_DW1:
	case CANPS_TXFIFO_DW2:
		CHECK_EQ(off, CANPS_TXFIFO_ID + 4u * txw_n);	/* the four words in order */
		txw[txw_n++ % 4] = v;
		if (off == CANPS_TXFIFO_DW2) {
			CHECK_EQ(txw_n, 4);
			CHECK(reg[CANPS_SRR / 4] & CANPS_SRR_CEN);
			if (n_sent < 256)
				memcpy(sent[n_sent++], txw, sizeof(txw));
			txw_n = 0;
			reg[CANPS_ISR / 4] |= CANPS_IXR_TXOK;
		}
		return;
	default:
		if (off >= CANPS_AFMR(0) && off <= CANPS_AFIR(3) && off != CANPS_AFR)
			CHECK_EQ(reg[CANPS_AFR / 4], 0);	/* filters written only while off */
		reg[off / 4] = v;
		return;
	}
}

static void sim_reset(void)
{
	memset(reg, 0, sizeof(reg));
	reg[CANPS_SR / 4] = CANPS_SR_CONFIG;
	rx_head = rx_n = 0;
	txw_n = 0;
	n_sent = 0;
	tx_full = 0;
	never_config = 0;
	writes_srr = 0;
}

/* ---- tests ---------------------------------------------------------- */

static const struct canps_filter filters[4] = {
	{ 0x780, 0x080 }, { 0x780, 0x180 }, { 0x780, 0x580 }, { 0x780, 0x700 },
};

static void test_timing(void)
{
	struct canps_timing t;
	uint32_t ts1, ts2;

	CHECK_EQ(canps_timing_for(100000000u, 1000000u, &t), 0);
	ts1 = (t.btr & 0xF) + 1;
	ts2 = ((t.btr >> 4) & 7) + 1;
	CHECK_EQ((t.brpr + 1) * (1 + ts1 + ts2), 100);	/* 100 reference clocks per bit */
	CHECK_EQ(1000 * (1 + ts1) / (1 + ts1 + ts2), 800);	/* sample point 80 % */
	CHECK_EQ((t.btr >> 7) & 3, 0);				/* SJW 1 */
	printf("timing: 1 Mbit/s from 100 MHz: brpr %u btr 0x%03x (tq %u, ts1 %u, ts2 %u)\n",
	       (unsigned)t.brpr, (unsigned)t.btr, (unsigned)(1 + ts1 + ts2), (unsigned)ts1, (unsigned)ts2);
	CHECK_EQ(canps_timing_for(100000000u, 500000u, &t), 0);
	CHECK_EQ((t.brpr + 1) * (1 + (t.btr & 0xF) + 1 + ((t.btr >> 4) & 7) + 1), 200);
	CHECK_EQ(canps_timing_for(100000000u, 3000000u, &t), -1);	/* not a whole number of tq */
	CHECK_EQ(canps_timing_for(100000000u, 0u, &t), -1);
}

static void test_init_send(struct canps *c)
{
	struct canps_timing t;
	struct can_frame f = { 0x201, 6, 0, { 0x0F, 0x00, 0x44, 0x33, 0x22, 0x11, 0xEE, 0xEE } };

	sim_reset();
	CHECK_EQ(canps_timing_for(100000000u, 1000000u, &t), 0);
	CHECK_EQ(canps_init(c, BASE, &t, filters, 4), 0);
	CHECK_EQ(reg[CANPS_BRPR / 4], t.brpr);
	CHECK_EQ(reg[CANPS_BTR / 4], t.btr);
	CHECK_EQ(reg[CANPS_AFR / 4], 0xF);
	CHECK_EQ(reg[CANPS_AFMR(1) / 4], (0x780u << 21) | CANPS_IDR_SRRRTR | CANPS_IDR_IDE);
	CHECK_EQ(reg[CANPS_AFIR(1) / 4], 0x180u << 21);
	CHECK(reg[CANPS_IER / 4] & CANPS_IXR_RXNEMP);
	CHECK(reg[CANPS_IER / 4] & CANPS_IXR_BSOFF);
	CHECK(reg[CANPS_IER / 4] & CANPS_IXR_ERROR);
	CHECK_EQ(reg[CANPS_SRR / 4], CANPS_SRR_CEN);
	CHECK_EQ(reg[CANPS_MSR / 4], 0);

	CHECK_EQ(canps_send(c, &f), 0);
	CHECK_EQ(n_sent, 1);
	CHECK_EQ(sent[0][0], 0x201u << 21);
	CHECK_EQ(sent[0][1], 6u << 28);
	CHECK_EQ(sent[0][2], 0x0F004433u);	/* DB0 in the top byte */
	CHECK_EQ(sent[0][3], 0x2211EEEEu);
	f.id = 0x080;
	f.dlc = 0;
	CHECK_EQ(canps_send(c, &f), 0);
	CHECK_EQ(sent[1][0], 0x080u << 21);
	f.rtr = 1;
	f.id = 0x701;
	CHECK_EQ(canps_send(c, &f), 0);
	CHECK_EQ(sent[2][0], (0x701u << 21) | CANPS_IDR_SRRRTR);
	CHECK_EQ(sent[2][2], 0);
	f.rtr = 0;
	tx_full = 1;
	CHECK_EQ(canps_send(c, &f), CANPS_BUSY);
	CHECK_EQ(c->st.tx_busy, 1);
	tx_full = 0;
	f.dlc = 9;
	CHECK_EQ(canps_send(c, &f), CANPS_EINVAL);
	f.dlc = 1;
	f.id = 0x800;
	CHECK_EQ(canps_send(c, &f), CANPS_EINVAL);
	CHECK_EQ(c->st.tx_bad, 2);
	CHECK_EQ(c->st.tx_frames, 3);
	CHECK_EQ(n_sent, 3);

	sim_reset();
	never_config = 1;
	CHECK_EQ(canps_init(c, BASE, &t, filters, 4), -1);
	CHECK_EQ(canps_init(c, BASE, &t, filters, 5), -1);
}

static void test_rx(struct canps *c)
{
	struct can_frame f;
	struct canps_timing t;

	sim_reset();
	CHECK_EQ(canps_timing_for(100000000u, 1000000u, &t), 0);
	CHECK_EQ(canps_init(c, BASE, &t, filters, 4), 0);
	rx_push(0x181u << 21, 6, 0x37020102u, 0x03040000u);
	rx_push(0x701u << 21, 1, 0x05000000u, 0);
	rx_push((0x123u << 21) | CANPS_IDR_IDE | CANPS_IDR_SRRRTR, 8, 0, 0);	/* extended */
	rx_push(0x581u << 21, 8, 0x60606000u, 0);
	canps_irq(c);
	CHECK_EQ(rx_n, 0);
	CHECK_EQ(reg[CANPS_ISR / 4] & (CANPS_IXR_RXNEMP | CANPS_IXR_RXOK), 0);
	CHECK_EQ(c->st.rx_frames, 4);
	CHECK_EQ(c->st.rx_bad, 1);
	CHECK_EQ(canps_recv(c, &f), 1);
	CHECK_EQ(f.id, 0x181);
	CHECK_EQ(f.dlc, 6);
	CHECK_EQ(f.data[0], 0x37);
	CHECK_EQ(f.data[1], 0x02);
	CHECK_EQ(f.data[2], 0x01);
	CHECK_EQ(f.data[3], 0x02);
	CHECK_EQ(f.data[4], 0x03);
	CHECK_EQ(f.data[5], 0x04);
	CHECK_EQ(canps_recv(c, &f), 1);
	CHECK_EQ(f.id, 0x701);
	CHECK_EQ(f.data[0], 5);
	CHECK_EQ(canps_recv(c, &f), 1);
	CHECK_EQ(f.id, 0x581);
	CHECK_EQ(canps_recv(c, &f), 0);

	/* more than the ring holds: the rest dropped and counted */
	for (unsigned i = 0; i < CANPS_RX_RING + 10; i++)
		rx_push((0x180u + (i & 0x7F)) << 21, 6, i, 0);
	canps_irq(c);
	CHECK_EQ(c->st.rx_dropped, 10);
	CHECK_EQ(c->st.ring_max, CANPS_RX_RING);
	for (unsigned i = 0; i < CANPS_RX_RING; i++) {
		CHECK_EQ(canps_recv(c, &f), 1);
		CHECK_EQ(f.data[3], (uint8_t)i);
	}
	CHECK_EQ(canps_recv(c, &f), 0);

	/* a DLC over 8 from the controller: dropped */
	rx_push(0x181u << 21, 15, 0, 0);
	canps_irq(c);
	CHECK_EQ(canps_recv(c, &f), 0);
	CHECK_EQ(c->st.rx_bad, 2);

	/* the drain is bounded: a FIFO that never empties does not hold the core */
	for (unsigned i = 0; i < 250; i++)
		rx_push(0x181u << 21, 6, 0, 0);
	canps_irq(c);
	CHECK_EQ(rx_n, 250 - 2 * CANPS_RX_RING);
	CHECK(reg[CANPS_ISR / 4] & CANPS_IXR_RXNEMP);	/* the line stays up for the rest */
	while (canps_recv(c, &f))
		;
	canps_irq(c);
	CHECK_EQ(rx_n, 0);

	/* RX overflow and underflow are counted and cleared */
	reg[CANPS_ISR / 4] |= CANPS_IXR_RXOFLW | CANPS_IXR_RXUFLW | CANPS_IXR_ARBLST;
	canps_irq(c);
	CHECK_EQ(c->st.rx_fifo_overflow, 1);
	CHECK_EQ(c->st.rx_underflow, 1);
	CHECK_EQ(c->st.arb_lost, 1);
	CHECK_EQ(reg[CANPS_ISR / 4] & (CANPS_IXR_RXOFLW | CANPS_IXR_RXUFLW | CANPS_IXR_ARBLST), 0);
	while (canps_recv(c, &f))
		;
}

static void test_errors_bus_off(struct canps *c)
{
	struct canps_timing t;
	struct can_frame f = { 0x080, 0, 0, { 0 } };
	unsigned srr0;

	sim_reset();
	CHECK_EQ(canps_timing_for(100000000u, 1000000u, &t), 0);
	CHECK_EQ(canps_init(c, BASE, &t, filters, 4), 0);
	/* errors with the counters in error passive */
	reg[CANPS_ESR / 4] = CANPS_ESR_ACKER | CANPS_ESR_BERR;
	reg[CANPS_ECR / 4] = (5u << 8) | 130u;
	reg[CANPS_SR / 4] = CANPS_SR_NORMAL | CANPS_SR_ERRWRN | (CANPS_ESTAT_PASSIVE << CANPS_SR_ESTAT_SHIFT);
	reg[CANPS_ISR / 4] |= CANPS_IXR_ERROR;
	canps_irq(c);
	CHECK_EQ(c->st.error_irqs, 1);
	CHECK_EQ(c->st.ack_errors, 1);
	CHECK_EQ(c->st.bit_errors, 1);
	CHECK_EQ(c->st.crc_errors, 0);
	CHECK_EQ(c->st.tec, 130);
	CHECK_EQ(c->st.rec, 5);
	CHECK_EQ(c->st.error_passive, 1);
	CHECK_EQ(c->st.error_warning, 1);
	CHECK_EQ(c->st.estat, CANPS_ESTAT_PASSIVE);
	CHECK_EQ(reg[CANPS_ESR / 4], 0);
	CHECK_EQ(reg[CANPS_ISR / 4] & CANPS_IXR_ERROR, 0);
	/* still passive: not counted again */
	reg[CANPS_ISR / 4] |= CANPS_IXR_ERROR;
	canps_irq(c);
	CHECK_EQ(c->st.error_passive, 1);
	CHECK_EQ(canps_service(c), 0);
	CHECK_EQ(c->st.error_passive, 1);
	/* back to active, then passive again: a second entry */
	reg[CANPS_SR / 4] = CANPS_SR_NORMAL | (CANPS_ESTAT_ACTIVE << CANPS_SR_ESTAT_SHIFT);
	CHECK_EQ(canps_service(c), 0);
	reg[CANPS_SR / 4] = CANPS_SR_NORMAL | (CANPS_ESTAT_PASSIVE << CANPS_SR_ESTAT_SHIFT);
	CHECK_EQ(canps_service(c), 0);
	CHECK_EQ(c->st.error_passive, 2);

	/* bus off: noted by the interrupt, nothing queued, restarted by service */
	reg[CANPS_SR / 4] = CANPS_ESTAT_BUSOFF << CANPS_SR_ESTAT_SHIFT;
	reg[CANPS_ISR / 4] |= CANPS_IXR_BSOFF;
	canps_irq(c);
	CHECK_EQ(c->st.bus_off, 1);
	CHECK_EQ(c->bus_off_pending, 1);
	CHECK_EQ(reg[CANPS_IER / 4] & CANPS_IXR_BSOFF, 0);
	CHECK_EQ(canps_send(c, &f), CANPS_BUSY);
	srr0 = writes_srr;
	CHECK_EQ(canps_service(c), 1);
	CHECK(writes_srr >= srr0 + 2);	/* reset, then enabled */
	CHECK_EQ(c->st.bus_off_recoveries, 1);
	CHECK_EQ(c->bus_off_pending, 0);
	CHECK_EQ(reg[CANPS_SRR / 4], CANPS_SRR_CEN);
	CHECK_EQ(reg[CANPS_AFR / 4], 0xF);
	CHECK(reg[CANPS_IER / 4] & CANPS_IXR_BSOFF);
	CHECK_EQ(canps_send(c, &f), 0);
	CHECK_EQ(canps_service(c), 0);
	/* a restart that fails is counted and retried */
	reg[CANPS_ISR / 4] |= CANPS_IXR_BSOFF;
	canps_irq(c);
	never_config = 1;
	CHECK_EQ(canps_service(c), 0);
	CHECK_EQ(c->st.restart_failed, 1);
	CHECK_EQ(c->bus_off_pending, 1);
	never_config = 0;
	CHECK_EQ(canps_service(c), 1);
	CHECK_EQ(c->st.bus_off, 2);
	CHECK_EQ(c->st.bus_off_recoveries, 2);

	canps_stop(c);
	CHECK_EQ(reg[CANPS_IER / 4], 0);
	CHECK_EQ(reg[CANPS_SRR / 4], 0);
}

int main(void)
{
	static struct canps c;

	test_timing();
	test_init_send(&c);
	test_rx(&c);
	test_errors_bus_off(&c);
	printf("canps: %d checks, %d failed\n", checks, failed);
	return failed ? 1 : 0;
}
