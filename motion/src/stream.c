/* SPDX-License-Identifier: MIT */
/* The input stage: byte stream with XOFF/XON watermarks, or a program in
 * memory (see stream.h). */
#define _POSIX_C_SOURCE 200809L
#include "stream.h"

#include <stdlib.h>
#include <string.h>

int stream_init(struct stream *s, const struct motion_config *cfg)
{
	uint32_t size = 1;

	pthread_mutex_init(&s->flow_lock, NULL);
	while (size < cfg->stream_size)
		size <<= 1;
	s->buf = calloc(size, 1);
	s->size = cfg->stream_size;
	s->mask = size - 1u;
	s->high = cfg->stream_high;
	s->low = cfg->stream_low;
	s->flow_cb = cfg->flow_cb;
	s->flow_user = cfg->flow_user;
	atomic_init(&s->flow, MOTION_FLOW_XON);
	atomic_init(&s->flow_lvl, 0);
	return s->buf ? 0 : -1;
}

void stream_free(struct stream *s)
{
	free(s->buf);
	pthread_mutex_destroy(&s->flow_lock);
}

uint32_t stream_backlog(const struct stream *s)
{
	return s->mem ? (uint32_t)(s->text_len - s->text_pos) : stream_level(s);
}

/* XOFF when the level reaches the high watermark, XON when it is back at
 * the low one; the lock is taken only near a watermark. */
static void flow_check(struct stream *s)
{
	uint32_t lvl = stream_level(s);
	int f = atomic_load(&s->flow);

	if ((f == MOTION_FLOW_XON && lvl < s->high) ||
	    (f == MOTION_FLOW_XOFF && lvl > s->low))
		return;
	pthread_mutex_lock(&s->flow_lock);
	lvl = stream_level(s);
	f = atomic_load(&s->flow);
	atomic_store(&s->flow_lvl, lvl);
	if (f == MOTION_FLOW_XON && lvl >= s->high) {
		atomic_store(&s->flow, MOTION_FLOW_XOFF);
		atomic_fetch_add(&s->xoff, 1);
		if (s->flow_cb)
			s->flow_cb(s->flow_user, MOTION_FLOW_XOFF);
	} else if (f == MOTION_FLOW_XOFF && lvl <= s->low) {
		atomic_store(&s->flow, MOTION_FLOW_XON);
		atomic_fetch_add(&s->xon, 1);
		if (s->flow_cb)
			s->flow_cb(s->flow_user, MOTION_FLOW_XON);
	}
	pthread_mutex_unlock(&s->flow_lock);
}

bool stream_closed(const struct stream *s)
{
	return atomic_load(&s->eos) || s->mem;
}

size_t stream_write(struct stream *s, const char *data, size_t len)
{
	uint32_t t = atomic_load_explicit(&s->tail, memory_order_relaxed);
	uint32_t h = atomic_load_explicit(&s->head, memory_order_acquire);
	uint32_t room = s->size - (t - h);
	size_t n = len < room ? len : room;
	uint32_t nl = 0;
	for (size_t i = 0; i < n; i++) {
		s->buf[(t + (uint32_t)i) & s->mask] = (unsigned char)data[i];
		nl += data[i] == '\n';
	}
	atomic_store_explicit(&s->tail, t + (uint32_t)n, memory_order_release);
	atomic_fetch_add_explicit(&s->lines_in, nl, memory_order_release);
	uint32_t lvl = t + (uint32_t)n - h;
	if (lvl > atomic_load_explicit(&s->peak, memory_order_relaxed))
		atomic_store_explicit(&s->peak, lvl, memory_order_relaxed);
	flow_check(s);
	return n;
}

void stream_end(struct stream *s)
{
	atomic_store(&s->eos, true);
}

void stream_load(struct stream *s, const char *text, size_t len)
{
	s->mem = true;
	s->text = text;
	s->text_len = len;
	s->text_pos = 0;
	uint32_t lines = 0;
	for (size_t i = 0; i < len; i++)
		lines += text[i] == '\n';
	if (len && text[len - 1] != '\n')
		lines++;
	s->text_lines = lines;
}

/* The next line of a program in memory. */
static int mem_next_line(struct stream *s, char *line, size_t *n)
{
	if (s->text_pos >= s->text_len)
		return 0;
	const char *p = s->text + s->text_pos;
	size_t rest = s->text_len - s->text_pos;
	const char *nl = memchr(p, '\n', rest);
	size_t l = nl ? (size_t)(nl - p) : rest;
	s->text_pos += nl ? l + 1 : l;
	s->text_lines_out++;
	if (l > MOTION_MAX_LINE)
		return 2;
	memcpy(line, p, l);
	*n = l;
	return 1;
}

int stream_next_line(struct stream *s, char *line, size_t *n)
{
	if (s->mem)
		return mem_next_line(s, line, n);
	uint32_t h = atomic_load_explicit(&s->head, memory_order_relaxed);
	uint32_t t = atomic_load_explicit(&s->tail, memory_order_acquire);
	uint32_t lvl = t - h;
	uint32_t lines = atomic_load_explicit(&s->lines_in, memory_order_acquire) -
			 s->lines_out;
	uint32_t scan = lvl < MOTION_MAX_LINE + 1u ? lvl : MOTION_MAX_LINE + 1u;
	uint32_t i;
	for (i = 0; i < scan; i++)
		if (s->buf[(h + i) & s->mask] == '\n')
			break;
	if (i < scan) { /* complete line of i characters */
		for (uint32_t k = 0; k < i; k++)
			line[k] = (char)s->buf[(h + k) & s->mask];
		*n = i;
		atomic_store_explicit(&s->head, h + i + 1u, memory_order_release);
		s->lines_out++;
		flow_check(s);
		return 1;
	}
	if (lvl > MOTION_MAX_LINE) {
		atomic_store_explicit(&s->head, h + scan, memory_order_release);
		flow_check(s);
		return 2;
	}
	if (lines == 0 && atomic_load(&s->eos) &&
	    lvl == stream_level(s) && lvl > 0) { /* last line without newline */
		for (uint32_t k = 0; k < lvl; k++)
			line[k] = (char)s->buf[(h + k) & s->mask];
		*n = lvl;
		atomic_store_explicit(&s->head, h + lvl, memory_order_release);
		flow_check(s);
		return 1;
	}
	return 0;
}

void stream_discard(struct stream *s)
{
	if (s->mem) {
		s->text_pos = s->text_len;
		s->text_lines_out = s->text_lines;
		return;
	}
	uint32_t t = atomic_load_explicit(&s->tail, memory_order_acquire);
	s->lines_out = atomic_load_explicit(&s->lines_in, memory_order_acquire);
	atomic_store_explicit(&s->head, t, memory_order_release);
	flow_check(s);
}

uint32_t stream_lines_taken(const struct stream *s)
{
	return s->mem ? s->text_lines_out : s->lines_out;
}
