/* SPDX-License-Identifier: MIT */
/*
 * canps.c - Zynq-7000 CAN controller driver (see canps.h).
 *
 * Concurrency: one producer of TX frames and one consumer of the RX ring,
 * both in the cycle handler; the controller's interrupt (higher priority
 * than the cycle) is the ring's only producer and touches only the RX
 * FIFO, the interrupt and error registers. The bus-off restart rewrites
 * every register, so it runs in the cycle (canps_service) with IRQs masked.
 * Never waits on the bus: the only loops are the RX drain (bounded by the
 * ring size plus the controller's FIFO) and the configuration-mode polls
 * after a reset (bounded, a few register reads).
 */
#include <stdint.h>

#include "canps.h"

#ifdef CANPS_HOST_TEST
/* Host unit test: the registers are a simulated controller. */
uint32_t canps_test_rd(uintptr_t addr);
void canps_test_wr(uintptr_t addr, uint32_t v);
#define RD(c, off) canps_test_rd((c)->base + (off))
#define WR(c, off, v) canps_test_wr((c)->base + (off), (v))
#define IRQ_SAVE() 0u
#define IRQ_RESTORE(f) ((void)(f))
#define BARRIER() __asm__ volatile("" ::: "memory")
#else
#include "arch.h"
#define RD(c, off) mmio_read32((c)->base + (off))
#define WR(c, off, v) mmio_write32((c)->base + (off), (v))
#define IRQ_SAVE() irq_save()
#define IRQ_RESTORE(f) irq_restore(f)
#define BARRIER() compiler_barrier()
#endif

#define CONFIG_POLLS 1000u
#define IER_BITS (CANPS_IXR_RXNEMP | CANPS_IXR_RXOFLW | CANPS_IXR_RXUFLW | CANPS_IXR_ERROR | \
		  CANPS_IXR_BSOFF | CANPS_IXR_ARBLST)

int canps_timing_for(uint32_t ref_hz, uint32_t bitrate, struct canps_timing *t)
{
	uint32_t best_err = UINT32_MAX;

	if (!bitrate || !t)
		return -1;
	for (uint32_t p = 1; p <= 256u; p++) {
		uint32_t n, ts1, ts2, err, sp;

		if (ref_hz % (bitrate * p))
			continue;
		n = ref_hz / (bitrate * p);	/* time quanta per bit */
		if (n < 8u || n > 25u)
			continue;
		ts2 = (n * 2u + 5u) / 10u;	/* about 20 % after the sample point */
		if (ts2 < 1u)
			ts2 = 1u;
		if (ts2 > 8u)
			ts2 = 8u;
		ts1 = n - 1u - ts2;
		if (ts1 > 16u) {
			ts1 = 16u;
			ts2 = n - 1u - ts1;
			if (ts2 > 8u)
				continue;
		}
		sp = 1000u * (1u + ts1) / n;
		err = sp > 800u ? sp - 800u : 800u - sp;
		if (err < best_err) {
			best_err = err;
			t->brpr = p - 1u;
			t->btr = (ts1 - 1u) | (ts2 - 1u) << 4;	/* SJW 1 (field 0) */
		}
	}
	return best_err == UINT32_MAX ? -1 : 0;
}

/* Reset into configuration mode and program everything but CEN. */
static int configure(struct canps *c)
{
	uint32_t i, afr = 0;

	WR(c, CANPS_IER, 0);
	WR(c, CANPS_SRR, CANPS_SRR_SRST);
	for (i = 0; i < CONFIG_POLLS && !(RD(c, CANPS_SR) & CANPS_SR_CONFIG); i++)
		;
	if (i == CONFIG_POLLS)
		return -1;
	WR(c, CANPS_MSR, 0);	/* normal mode once enabled */
	WR(c, CANPS_BRPR, c->timing.brpr);
	WR(c, CANPS_BTR, c->timing.btr);
	WR(c, CANPS_AFR, 0);	/* filters may be written only while unused */
	for (i = 0; i < CONFIG_POLLS && (RD(c, CANPS_SR) & CANPS_SR_ACFBSY); i++)
		;
	for (i = 0; i < c->n_filters; i++) {
		/* standard data frames only: IDE and RTR compared too (0) */
		WR(c, CANPS_AFMR(i), CANPS_IDR_STD(c->filter[i].mask) | CANPS_IDR_SRRRTR | CANPS_IDR_IDE);
		WR(c, CANPS_AFIR(i), CANPS_IDR_STD(c->filter[i].match));
		afr |= 1u << i;
	}
	WR(c, CANPS_AFR, afr);
	WR(c, CANPS_ICR, CANPS_IXR_ALL);
	WR(c, CANPS_ESR, 0x1Fu);
	c->last_estat = CANPS_ESTAT_ACTIVE;
	c->last_errwrn = 0;
	WR(c, CANPS_IER, IER_BITS);
	WR(c, CANPS_SRR, CANPS_SRR_CEN);
	return 0;
}

int canps_init(struct canps *c, uintptr_t base, const struct canps_timing *t,
	       const struct canps_filter *filters, uint32_t n_filters)
{
	if (!c || !t || n_filters > 4u || (n_filters && !filters))
		return -1;
	c->base = base;
	c->timing = *t;
	c->n_filters = n_filters;
	for (uint32_t i = 0; i < 4u; i++)
		c->filter[i] = i < n_filters ? filters[i] : (struct canps_filter){ 0, 0 };
	c->head = c->tail = 0;
	c->bus_off_pending = 0;
	c->st = (struct canps_stats){ 0 };
	c->st.estat = CANPS_ESTAT_ACTIVE;
	return configure(c);
}

void canps_stop(struct canps *c)
{
	WR(c, CANPS_IER, 0);
	WR(c, CANPS_SRR, 0);	/* configuration mode: off the bus */
	WR(c, CANPS_ICR, CANPS_IXR_ALL);
}

int canps_send(struct canps *c, const struct can_frame *f)
{
	uint32_t dw1, dw2;

	if (f->dlc > 8u || f->id > 0x7FFu) {
		c->st.tx_bad++;
		return CANPS_EINVAL;
	}
	if (c->bus_off_pending || (RD(c, CANPS_SR) & CANPS_SR_TXFLL)) {
		c->st.tx_busy++;
		return CANPS_BUSY;
	}
	/* DB0 is the most significant byte of DW1 */
	dw1 = (uint32_t)f->data[0] << 24 | (uint32_t)f->data[1] << 16 | (uint32_t)f->data[2] << 8 | f->data[3];
	dw2 = (uint32_t)f->data[4] << 24 | (uint32_t)f->data[5] << 16 | (uint32_t)f->data[6] << 8 | f->data[7];
	if (f->rtr)
		dw1 = dw2 = 0;
	WR(c, CANPS_TXFIFO_ID, CANPS_IDR_STD(f->id) | (f->rtr ? CANPS_IDR_SRRRTR : 0u));
	WR(c, CANPS_TXFIFO_DLC, (uint32_t)f->dlc << 28);
	WR(c, CANPS_TXFIFO_DW1, dw1);
	WR(c, CANPS_TXFIFO_DW2, dw2);	/* the last word starts the transfer */
	c->st.tx_frames++;
	return 0;
}

int canps_recv(struct canps *c, struct can_frame *f)
{
	uint32_t t = c->tail;

	if (t == c->head)
		return 0;
	BARRIER();
	*f = c->ring[t % CANPS_RX_RING];
	BARRIER();
	c->tail = t + 1u;
	return 1;
}

static void read_errors(struct canps *c)
{
	uint32_t ecr = RD(c, CANPS_ECR), sr = RD(c, CANPS_SR);
	uint32_t estat = (sr & CANPS_SR_ESTAT_MASK) >> CANPS_SR_ESTAT_SHIFT;
	uint32_t wrn = (sr & CANPS_SR_ERRWRN) ? 1u : 0u;

	c->st.tec = ecr & 0xFFu;
	c->st.rec = (ecr >> 8) & 0xFFu;
	if (c->st.tec > c->st.tec_max)
		c->st.tec_max = c->st.tec;
	if (c->st.rec > c->st.rec_max)
		c->st.rec_max = c->st.rec;
	if (estat == 0u)
		return;	/* configuration mode: no error state */
	if (estat == CANPS_ESTAT_PASSIVE && c->last_estat != CANPS_ESTAT_PASSIVE)
		c->st.error_passive++;
	if (wrn && !c->last_errwrn)
		c->st.error_warning++;
	c->last_estat = estat;
	c->last_errwrn = wrn;
	c->st.estat = estat;
}

void canps_irq(void *arg)
{
	struct canps *c = arg;
	uint32_t isr = RD(c, CANPS_ISR), clr = 0;

	c->st.irqs++;
	/* Drain the RX FIFO: at most its depth plus what arrives meanwhile. */
	for (uint32_t n = 0; (isr & CANPS_IXR_RXNEMP) && n < 2u * CANPS_RX_RING; n++) {
		uint32_t id = RD(c, CANPS_RXFIFO_ID), dlc = RD(c, CANPS_RXFIFO_DLC) >> 28;
		uint32_t dw1 = RD(c, CANPS_RXFIFO_DW1), dw2 = RD(c, CANPS_RXFIFO_DW2);
		uint32_t h = c->head;

		WR(c, CANPS_ICR, CANPS_IXR_RXNEMP | CANPS_IXR_RXOK);
		isr = RD(c, CANPS_ISR);
		c->st.rx_frames++;
		if ((id & CANPS_IDR_IDE) || dlc > 8u) {
			c->st.rx_bad++;	/* not ours: extended frames, a DLC over 8 */
			continue;
		}
		if (h - c->tail >= CANPS_RX_RING) {
			c->st.rx_dropped++;
			continue;
		}
		{
			struct can_frame *f = &c->ring[h % CANPS_RX_RING];

			f->id = id >> 21;
			f->rtr = (id & CANPS_IDR_SRRRTR) ? 1u : 0u;
			f->dlc = (uint8_t)dlc;
			for (uint32_t b = 0; b < 4u; b++) {
				f->data[b] = (uint8_t)(dw1 >> (24u - 8u * b));
				f->data[4u + b] = (uint8_t)(dw2 >> (24u - 8u * b));
			}
		}
		BARRIER();
		c->head = h + 1u;
		if (h + 1u - c->tail > c->st.ring_max)
			c->st.ring_max = h + 1u - c->tail;
	}
	if (isr & CANPS_IXR_RXOFLW) {
		c->st.rx_fifo_overflow++;
		clr |= CANPS_IXR_RXOFLW;
	}
	if (isr & CANPS_IXR_RXUFLW) {
		c->st.rx_underflow++;
		clr |= CANPS_IXR_RXUFLW;
	}
	if (isr & CANPS_IXR_ARBLST) {
		c->st.arb_lost++;
		clr |= CANPS_IXR_ARBLST;
	}
	if (isr & CANPS_IXR_ERROR) {
		uint32_t esr = RD(c, CANPS_ESR);

		c->st.error_irqs++;
		c->st.ack_errors += (esr & CANPS_ESR_ACKER) ? 1u : 0u;
		c->st.bit_errors += (esr & CANPS_ESR_BERR) ? 1u : 0u;
		c->st.stuff_errors += (esr & CANPS_ESR_STER) ? 1u : 0u;
		c->st.form_errors += (esr & CANPS_ESR_FMER) ? 1u : 0u;
		c->st.crc_errors += (esr & CANPS_ESR_CRCER) ? 1u : 0u;
		WR(c, CANPS_ESR, esr & 0x1Fu);
		clr |= CANPS_IXR_ERROR;
		read_errors(c);
	}
	if (isr & CANPS_IXR_BSOFF) {
		/* Off the bus: restarted from the cycle (canps_service); until
		 * then nothing is queued and this source stays quiet. */
		if (!c->bus_off_pending)
			c->st.bus_off++;
		c->bus_off_pending = 1;
		WR(c, CANPS_IER, IER_BITS & ~CANPS_IXR_BSOFF);
		clr |= CANPS_IXR_BSOFF;
	}
	/* RXNEMP still set after the bound: the rest is left for the next
	 * interrupt (the line stays high). */
	clr |= isr & (CANPS_IXR_TXOK | CANPS_IXR_RXOK);
	if (clr)
		WR(c, CANPS_ICR, clr);
}

int canps_service(struct canps *c)
{
	uint32_t flags;
	int rc = 0;

	if (c->bus_off_pending) {
		flags = IRQ_SAVE();
		if (configure(c) == 0) {
			c->st.bus_off_recoveries++;
			c->st.estat = CANPS_ESTAT_ACTIVE;
			c->bus_off_pending = 0;
			rc = 1;
		} else {
			c->st.restart_failed++;
		}
		IRQ_RESTORE(flags);
		return rc;
	}
	flags = IRQ_SAVE();
	read_errors(c);
	IRQ_RESTORE(flags);
	return 0;
}

void canps_get_stats(const struct canps *c, struct canps_stats *out)
{
	*out = c->st;
}
