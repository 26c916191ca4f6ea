/* SPDX-License-Identifier: MIT */
#ifndef RPU_UART_H
#define RPU_UART_H

#include <stdint.h>

/* Initialise the console UART; 0 if usable, -1 if its clock is gated. */
int uart_init(void);
int uart_ready(void);
/* Non-blocking: 1 if the byte was queued in the TX FIFO, 0 if full. */
int uart_try_putc(char c);
/* Wait until the transmitter is empty (bounded), for the stop path. */
void uart_drain(void);

#endif
