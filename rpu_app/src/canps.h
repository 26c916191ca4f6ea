/* SPDX-License-Identifier: MIT */
#ifndef RPU_CANPS_H
#define RPU_CANPS_H

#include <stdint.h>

#include "can_frame.h"

/*
 * canps.c - bare-metal driver of the Zynq-7000 CAN controller (CANPS,
 * UG585 chapter 18 / appendix B.5; the same IP as QEMU's xlnx-zynqmp-can):
 * standard identifiers, classic frames.
 *
 *  - canps_init: software reset (configuration mode), bit timing, up to 4
 *    acceptance filters, interrupts, normal mode;
 *  - canps_send: one frame into the TX FIFO, never waits: CANPS_BUSY when
 *    the FIFO is full (or while a bus-off restart is pending);
 *  - canps_irq (the controller's interrupt handler): drains the RX FIFO
 *    (RXNEMP/RXOK) into a fixed ring, counts RX overflow, error status
 *    (ack, bit, stuff, form, CRC), error counters and state (warning,
 *    passive), and notes a bus-off;
 *  - canps_recv (one consumer, the cycle): the next frame of the ring;
 *  - canps_service (the cycle, before sending): a noted bus-off restarts
 *    the controller (counted); returns 1 when it did.
 * All counters are in struct canps_stats.
 */

#define CANPS_RX_RING 64u	/* frames; power of two */
#define CANPS_BUSY 1
#define CANPS_EINVAL (-1)

/* Register offsets (UG585 B.5). */
#define CANPS_SRR 0x00u		/* software reset: SRST bit 0, CEN bit 1 */
#define CANPS_MSR 0x04u		/* mode select: SLEEP 0, LBACK 1, SNOOP 2 */
#define CANPS_BRPR 0x08u	/* baud rate prescaler (value + 1) */
#define CANPS_BTR 0x0Cu		/* bit timing: TS1 [3:0], TS2 [6:4], SJW [8:7] */
#define CANPS_ECR 0x10u		/* error counters: TEC [7:0], REC [15:8] */
#define CANPS_ESR 0x14u		/* error status (write 1 to clear) */
#define CANPS_SR 0x18u		/* status */
#define CANPS_ISR 0x1Cu
#define CANPS_IER 0x20u
#define CANPS_ICR 0x24u
#define CANPS_TCR 0x28u
#define CANPS_WIR 0x2Cu
#define CANPS_TXFIFO_ID 0x30u
#define CANPS_TXFIFO_DLC 0x34u
#define CANPS_TXFIFO_DW1 0x38u
#define CANPS_TXFIFO_DW2 0x3Cu
#define CANPS_RXFIFO_ID 0x50u
#define CANPS_RXFIFO_DLC 0x54u
#define CANPS_RXFIFO_DW1 0x58u
#define CANPS_RXFIFO_DW2 0x5Cu
#define CANPS_AFR 0x60u
#define CANPS_AFMR(n) (0x64u + 8u * (n))	/* n = 0..3 */
#define CANPS_AFIR(n) (0x68u + 8u * (n))

#define CANPS_SRR_SRST (1u << 0)
#define CANPS_SRR_CEN (1u << 1)
#define CANPS_SR_CONFIG (1u << 0)
#define CANPS_SR_NORMAL (1u << 3)
#define CANPS_SR_ERRWRN (1u << 6)
#define CANPS_SR_ESTAT_SHIFT 7u
#define CANPS_SR_ESTAT_MASK (3u << 7)	/* 0 config, 1 active, 2 passive, 3 bus off */
#define CANPS_SR_TXFLL (1u << 10)
#define CANPS_SR_ACFBSY (1u << 11)
#define CANPS_ESTAT_ACTIVE 1u
#define CANPS_ESTAT_PASSIVE 2u
#define CANPS_ESTAT_BUSOFF 3u

#define CANPS_IXR_ARBLST (1u << 0)
#define CANPS_IXR_TXOK (1u << 1)
#define CANPS_IXR_TXFLL (1u << 2)
#define CANPS_IXR_RXOK (1u << 4)
#define CANPS_IXR_RXUFLW (1u << 5)
#define CANPS_IXR_RXOFLW (1u << 6)
#define CANPS_IXR_RXNEMP (1u << 7)
#define CANPS_IXR_ERROR (1u << 8)
#define CANPS_IXR_BSOFF (1u << 9)
#define CANPS_IXR_ALL 0x7FFFu

#define CANPS_ESR_CRCER (1u << 0)
#define CANPS_ESR_FMER (1u << 1)
#define CANPS_ESR_STER (1u << 2)
#define CANPS_ESR_BERR (1u << 3)
#define CANPS_ESR_ACKER (1u << 4)

/* ID register layout (TX/RX FIFO, filters): standard ID in IDH [31:21],
 * SRR/RTR [20], IDE [19]. */
#define CANPS_IDR_STD(id) (((uint32_t)(id) & 0x7FFu) << 21)
#define CANPS_IDR_SRRRTR (1u << 20)
#define CANPS_IDR_IDE (1u << 19)

/* Bit timing, register values (BRPR = prescaler - 1; TS1/TS2/SJW - 1). */
struct canps_timing {
	uint32_t brpr;
	uint32_t btr;
};

/* An acceptance filter on standard data frames: (id & mask) == (match & mask). */
struct canps_filter {
	uint16_t mask;		/* 11-bit */
	uint16_t match;
};

struct canps_stats {
	uint32_t tx_frames;		/* frames written to the TX FIFO */
	uint32_t tx_busy;		/* refused: TX FIFO full or bus-off pending */
	uint32_t tx_bad;		/* refused: DLC > 8 or ID > 11 bits */
	uint32_t rx_frames;		/* frames drained from the RX FIFO */
	uint32_t rx_dropped;		/* the ring was full */
	uint32_t rx_bad;		/* extended ID or DLC > 8 from the controller: dropped */
	uint32_t rx_fifo_overflow;	/* RXOFLW: the controller's FIFO overflowed */
	uint32_t rx_underflow;		/* RXUFLW */
	uint32_t irqs;
	uint32_t error_irqs;		/* ERROR interrupts */
	uint32_t ack_errors, bit_errors, stuff_errors, form_errors, crc_errors;
	uint32_t arb_lost;
	uint32_t error_warning;		/* entries into error warning (ERRWRN) */
	uint32_t error_passive;		/* entries into error passive */
	uint32_t bus_off;		/* bus-off events */
	uint32_t bus_off_recoveries;	/* controller restarts after a bus-off */
	uint32_t restart_failed;	/* restarts that did not reach configuration mode */
	uint32_t tec, rec;		/* error counters, last read */
	uint32_t tec_max, rec_max;
	uint32_t estat;			/* last error state (CANPS_ESTAT_*) */
	uint32_t ring_max;		/* most frames waiting in the ring */
};

struct canps {
	uintptr_t base;
	struct canps_timing timing;
	struct canps_filter filter[4];
	uint32_t n_filters;
	volatile uint32_t head;		/* written by the interrupt handler */
	volatile uint32_t tail;		/* written by the consumer */
	volatile uint32_t bus_off_pending;
	uint32_t last_estat, last_errwrn;
	struct can_frame ring[CANPS_RX_RING];
	struct canps_stats st;
};

/*
 * Bit timing for bitrate from ref_hz: the smallest prescaler giving 8..25
 * time quanta per bit, sample point near 80 %. 0, or -1 if unreachable.
 */
int canps_timing_for(uint32_t ref_hz, uint32_t bitrate, struct canps_timing *t);

/* 0, or -1 (bad arguments, configuration mode not reached). */
int canps_init(struct canps *c, uintptr_t base, const struct canps_timing *t,
	       const struct canps_filter *filters, uint32_t n_filters);
/* 0 queued, CANPS_BUSY, CANPS_EINVAL. Cycle context only (one producer). */
int canps_send(struct canps *c, const struct can_frame *f);
/* 1 and *f filled, or 0 when the ring is empty. One consumer. */
int canps_recv(struct canps *c, struct can_frame *f);
/* Bus-off restart if one is pending (1: restarted), error counters read. */
int canps_service(struct canps *c);
/* The controller's interrupt handler (arg: struct canps *). */
void canps_irq(void *arg);
/* Quiesce: interrupts off, configuration mode (stop path). */
void canps_stop(struct canps *c);
void canps_get_stats(const struct canps *c, struct canps_stats *out);

#endif
