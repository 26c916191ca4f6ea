/* SPDX-License-Identifier: MIT */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>

#include "arch.h"
#include "board.h"
#include "log.h"
#include "uart.h"

#define LINE_MAX  256u
#define UART_RING 4096u		/* power of two */

/* Trace buffer: section .trace lies in the non-cacheable carveout top. */
char trace_buf[BOARD_TRACE_SIZE] __attribute__((section(".trace"), aligned(32)));

static uint32_t trace_pos;
static uint32_t trace_wraps;
static char uring[UART_RING];
static volatile uint32_t uhead;	/* written by producers (IRQs masked) */
static volatile uint32_t utail;	/* written by the consumer (main loop) */
static uint32_t udropped;

void log_init(void)
{
	trace_pos = 0;
	trace_wraps = 0;
	uhead = utail = 0;
	udropped = 0;
	/* The buffer is NOLOAD: start from an empty string, and write the
	 * whole buffer once so no stale text of an earlier run shows. */
	for (uint32_t i = 0; i < BOARD_TRACE_SIZE; i++)
		trace_buf[i] = 0;
}

static void trace_putc(char c)
{
	trace_buf[trace_pos++] = c;
	if (trace_pos >= BOARD_TRACE_SIZE - 1u) {
		trace_pos = 0;
		trace_wraps++;
	}
	trace_buf[trace_pos] = 0;
}

static void uring_putc(char c)
{
	uint32_t h = uhead;

	if (h - utail >= UART_RING) {
		udropped++;
		return;
	}
	uring[h & (UART_RING - 1u)] = c;
	compiler_barrier();
	uhead = h + 1u;
}

static void commit(const char *s, uint32_t n)
{
	uint32_t flags = irq_save();

	for (uint32_t i = 0; i < n; i++) {
		trace_putc(s[i]);
		if (s[i] == '\n')
			uring_putc('\r');
		uring_putc(s[i]);
	}
	irq_restore(flags);
}

void log_poll(void)
{
	uint32_t t = utail;

	while (t != uhead) {
		if (!uart_try_putc(uring[t & (UART_RING - 1u)]))
			break;
		t++;
	}
	utail = t;
}

void log_flush(void)
{
	for (uint32_t i = 0; i < 1000000u && utail != uhead; i++)
		log_poll();
	uart_drain();
}

void log_get_stats(struct log_stats *st)
{
	st->trace_wraps = trace_wraps;
	st->trace_pos = trace_pos;
	st->uart_dropped = udropped;
}

/* ---- formatter ---------------------------------------------------- */
struct out {
	char *buf;
	uint32_t size;
	uint32_t len;
};

static void out_c(struct out *o, char c)
{
	if (o->len + 1u < o->size)
		o->buf[o->len] = c;
	o->len++;
}

static void out_num(struct out *o, unsigned long long v, unsigned base, int upper,
		    int neg, unsigned width, int zero, int left)
{
	char tmp[24];
	unsigned n = 0, total;
	const char *digits = upper ? "0123456789ABCDEF" : "0123456789abcdef";

	do {
		tmp[n++] = digits[v % base];
		v /= base;
	} while (v && n < sizeof(tmp));
	total = n + (neg ? 1u : 0u);
	if (neg && zero)
		out_c(o, '-');
	if (!left)
		for (; total < width; total++)
			out_c(o, zero ? '0' : ' ');
	if (neg && !zero)
		out_c(o, '-');
	while (n)
		out_c(o, tmp[--n]);
	if (left)
		for (; total < width; total++)
			out_c(o, ' ');
}

static void vformat(struct out *o, const char *fmt, va_list ap)
{
	for (; *fmt; fmt++) {
		unsigned width = 0;
		int zero = 0, left = 0, lng = 0;

		if (*fmt != '%') {
			out_c(o, *fmt);
			continue;
		}
		fmt++;
		for (;; fmt++) {
			if (*fmt == '0')
				zero = 1;
			else if (*fmt == '-')
				left = 1;
			else
				break;
		}
		while (*fmt >= '0' && *fmt <= '9')
			width = width * 10u + (unsigned)(*fmt++ - '0');
		while (*fmt == 'l') {
			lng++;
			fmt++;
		}
		if (*fmt == 'z')
			fmt++;
		switch (*fmt) {
		case 'd':
		case 'i': {
			long long v = lng >= 2 ? va_arg(ap, long long) :
				      lng == 1 ? va_arg(ap, long) : va_arg(ap, int);
			unsigned long long u = v < 0 ? 0ull - (unsigned long long)v : (unsigned long long)v;

			out_num(o, u, 10, 0, v < 0, width, zero, left);
			break;
		}
		case 'u':
		case 'x':
		case 'X': {
			unsigned long long v = lng >= 2 ? va_arg(ap, unsigned long long) :
					       lng == 1 ? va_arg(ap, unsigned long) : va_arg(ap, unsigned);

			out_num(o, v, *fmt == 'u' ? 10u : 16u, *fmt == 'X', 0, width, zero, left);
			break;
		}
		case 'p':
			out_c(o, '0');
			out_c(o, 'x');
			out_num(o, (uintptr_t)va_arg(ap, void *), 16, 0, 0, 8, 1, 0);
			break;
		case 's': {
			const char *s = va_arg(ap, const char *);
			unsigned n = 0;

			if (!s)
				s = "(null)";
			for (const char *p = s; *p; p++)
				n++;
			if (!left)
				for (; n < width; n++)
					out_c(o, ' ');
			while (*s)
				out_c(o, *s++);
			if (left)
				for (; n < width; n++)
					out_c(o, ' ');
			break;
		}
		case 'c':
			out_c(o, (char)va_arg(ap, int));
			break;
		case '%':
			out_c(o, '%');
			break;
		case '\0':
			return;
		default:
			out_c(o, '%');
			out_c(o, *fmt);
			break;
		}
	}
}

int log_snprintf(char *buf, uint32_t size, const char *fmt, ...)
{
	struct out o = { buf, size, 0 };
	va_list ap;

	va_start(ap, fmt);
	vformat(&o, fmt, ap);
	va_end(ap);
	if (size)
		buf[o.len < size ? o.len : size - 1u] = 0;
	return (int)o.len;
}

void log_vprintf(const char *fmt, va_list ap)
{
	char line[LINE_MAX];
	struct out o = { line, sizeof(line), 0 };
	uint32_t n;

	vformat(&o, fmt, ap);
	n = o.len < sizeof(line) ? o.len : (uint32_t)sizeof(line) - 1u;
	if (o.len >= sizeof(line))
		line[n - 1u] = '\n';	/* truncated: keep lines whole */
	commit(line, n);
}

void log_printf(const char *fmt, ...)
{
	va_list ap;

	va_start(ap, fmt);
	log_vprintf(fmt, ap);
	va_end(ap);
}
