/* SPDX-License-Identifier: MIT */
/*
 * The input stage: the program text, either a byte stream written by a
 * host thread (a ring with XOFF/XON watermarks) or a whole program in
 * memory.  The decoder takes it one line at a time.
 */
#ifndef SERVOAMP_MOTION_STREAM_H
#define SERVOAMP_MOTION_STREAM_H

#include <pthread.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "motion/motion.h"
#include "motion/ring.h"

/* The writer's and the decoder's fields are on separate cache lines, so a
 * host thread writing the stream and a worker decoding it do not bounce
 * one line per line of G-code. */
struct stream {
	unsigned char *buf;
	uint32_t size, mask;
	uint32_t high, low;
	void (*flow_cb)(void *user, enum motion_flow ev);
	void *flow_user;
	/* memory program (read-only after stream_load) */
	bool mem;
	const char *text;
	size_t text_len;
	uint32_t text_lines;
	/* writer side */
	_Alignas(RING_CACHELINE) _Atomic uint32_t tail; /* free-running byte index */
	_Atomic uint32_t lines_in;            /* newlines written */
	_Atomic uint32_t peak;
	atomic_bool eos;
	/* decoder side */
	_Alignas(RING_CACHELINE) _Atomic uint32_t head; /* free-running byte index */
	_Atomic uint32_t lines_out;           /* newlines consumed */
	_Atomic size_t text_pos;
	_Atomic uint32_t text_lines_out;
	/* flow control (both sides, only at the watermarks) */
	_Alignas(RING_CACHELINE) pthread_mutex_t flow_lock;
	atomic_int flow;
	_Atomic uint32_t flow_lvl;	/* level at the latest XOFF/XON */
	_Atomic uint64_t xoff, xon;
};

/* Setup (allocates the byte ring); 0 or -1. */
int stream_init(struct stream *s, const struct motion_config *cfg);
void stream_free(struct stream *s);

/* Writer: copies up to len bytes, as many as there is room for; returns
 * the number taken. */
size_t stream_write(struct stream *s, const char *data, size_t len);
/* No more input: stream ended, or a program loaded. */
bool stream_closed(const struct stream *s);
void stream_end(struct stream *s);
/* A whole program in memory instead of the byte ring (not copied). */
void stream_load(struct stream *s, const char *text, size_t len);

/* Bytes buffered in the byte ring. */
static inline uint32_t stream_level(const struct stream *s)
{
	return atomic_load_explicit(&s->tail, memory_order_acquire) -
	       atomic_load_explicit(&s->head, memory_order_acquire);
}

/* What is left to decode: bytes in the ring, or of the program. */
uint32_t stream_backlog(const struct stream *s);

/* Decoder: copies the next line (without its newline) into line[] (room
 * for MOTION_MAX_LINE characters).  Returns 1 with *n set, 0 if no
 * complete line is available, 2 if the line is too long (consumed up to
 * MOTION_MAX_LINE + 1 characters). */
int stream_next_line(struct stream *s, char *line, size_t *n);
/* Lines (or the equivalent) the decoder can take now (the scheduler asks
 * at every decision, hence inline). */
static inline uint32_t stream_avail(const struct stream *s)
{
	if (s->mem)
		return s->text_lines - s->text_lines_out;
	uint32_t lines = atomic_load_explicit(&s->lines_in, memory_order_acquire) -
			 s->lines_out;
	if (lines)
		return lines;
	uint32_t lvl = stream_level(s);
	if (lvl > MOTION_MAX_LINE)
		return 1;
	if (lvl > 0 && atomic_load(&s->eos))
		return 1;
	return 0;
}

/* The input has ended and every line was taken. */
static inline bool stream_eof(const struct stream *s)
{
	return atomic_load(&s->eos) && stream_avail(s) == 0;
}

/* Drops everything buffered (after the end of the program or an error). */
void stream_discard(struct stream *s);
/* Lines the decoder has taken so far. */
uint32_t stream_lines_taken(const struct stream *s);

#endif
