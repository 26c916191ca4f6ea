/* SPDX-License-Identifier: MIT */
#ifndef RPU_LOG_H
#define RPU_LOG_H

#include <stdarg.h>
#include <stdint.h>

/*
 * printf-like logger to two sinks:
 *  - the remoteproc trace buffer (in the non-cacheable top of the carveout,
 *    declared by the RSC_TRACE entry): a ring kept NUL-terminated, as
 *    Linux's debugfs remoteprocN/trace0 reads it (from the start up to the
 *    first NUL);
 *  - the console UART, through a software ring drained without blocking
 *    by log_poll() in the main loop, so logging never waits for the UART
 *    in interrupt context.
 * Safe from any context: a line is committed with IRQs masked.
 * Formats: %d %i %u %x %X %p %s %c %%, flags '-' '0', width, 'l', 'll'.
 */
void log_init(void);
void log_printf(const char *fmt, ...) __attribute__((format(printf, 1, 2)));
void log_vprintf(const char *fmt, va_list ap);
int log_snprintf(char *buf, uint32_t size, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
void log_poll(void);		/* move queued bytes to the UART, non-blocking */
void log_flush(void);		/* wait until everything queued was sent */

struct log_stats {
	uint32_t trace_wraps;
	uint32_t trace_pos;
	uint32_t uart_dropped;
};
void log_get_stats(struct log_stats *st);

extern char trace_buf[];

#endif
