/* SPDX-License-Identifier: MIT */
/*
 * uart.c - Cadence UART (Zynq-7000 PS UART) transmitter, polled.
 * The UART is owned by the firmware (Linux's devicetree disables it).
 */
#include "arch.h"
#include "board.h"
#include "uart.h"

#define UART_CR      0x00u
#define UART_MR      0x04u
#define UART_IDR     0x0cu
#define UART_BAUDGEN 0x18u
#define UART_SR      0x2cu
#define UART_FIFO    0x30u
#define UART_BAUDDIV 0x34u

#define CR_RXRST  (1u << 0)
#define CR_TXRST  (1u << 1)
#define CR_RXEN   (1u << 2)
#define CR_RXDIS  (1u << 3)
#define CR_TXEN   (1u << 4)
#define CR_TXDIS  (1u << 5)
#define CR_STPBRK (1u << 8)
#define MR_8N1    0x20u		/* 8 data bits, no parity, 1 stop */
#define SR_TXEMPTY (1u << 3)
#define SR_TXFULL  (1u << 4)

/* SLCR UART_CLK_CTRL: CLKACT0 = bit 0, CLKACT1 = bit 1. */
#define SLCR_UART_CLK_CTRL 0x154u

static int ready;

static uint32_t rd(uint32_t off)
{
	return mmio_read32(BOARD_UART_BASE + off);
}

static void wr(uint32_t off, uint32_t v)
{
	mmio_write32(BOARD_UART_BASE + off, v);
}

int uart_init(void)
{
	uint32_t bdiv = 6u, cd;

	ready = 0;
#if BOARD_HAS_SLCR
	/* A gated UART makes every access fault (QEMU: bus error). */
	if (!(mmio_read32(BOARD_SLCR_BASE + SLCR_UART_CLK_CTRL) & ((BOARD_UART_BASE & 0x1000u) ? 2u : 1u)))
		return -1;
#endif
	cd = BOARD_UART_REF_HZ / (BOARD_UART_BAUD * (bdiv + 1u));
	if (cd < 2u)
		cd = 2u;
	wr(UART_CR, CR_TXDIS | CR_RXDIS);
	wr(UART_IDR, 0x1fffu);
	wr(UART_MR, MR_8N1);
	wr(UART_BAUDGEN, cd);
	wr(UART_BAUDDIV, bdiv);
	wr(UART_CR, CR_TXRST | CR_RXRST);
	wr(UART_CR, CR_TXEN | CR_RXEN | CR_STPBRK);
	ready = 1;
	return 0;
}

int uart_ready(void)
{
	return ready;
}

int uart_try_putc(char c)
{
	if (!ready)
		return 1;	/* no console: drop silently (trace still has it) */
	if (rd(UART_SR) & SR_TXFULL)
		return 0;
	wr(UART_FIFO, (uint8_t)c);
	return 1;
}

void uart_drain(void)
{
	if (!ready)
		return;
	for (uint32_t i = 0; i < 2000000u && !(rd(UART_SR) & SR_TXEMPTY); i++)
		;
}
