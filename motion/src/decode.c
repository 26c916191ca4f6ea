/* SPDX-License-Identifier: MIT */
/* The decode stage (see decode.h). */
#include "decode.h"

#include <string.h>

#include "pipeline.h"

void decode_init(struct decode *d, struct motion *m,
		 const struct motion_config *cfg, struct stream *in,
		 struct ring *out)
{
	d->m = m;
	d->in = in;
	d->out = out;
	d->batch = cfg->batch;
	gc_init(&d->gc, cfg);
}

void decode_levels(void *arg, uint32_t *ul, uint32_t *dl, uint32_t *dcap)
{
	struct decode *d = arg;

	*dl = ring_count(d->out);
	*dcap = d->out->cap;
	if (d->end_sent) {
		*ul = d->stop ? stream_avail(d->in) : 0; /* discard after the end */
		if (*ul)
			*dl = 0; /* discarding needs no room */
		return;
	}
	if (d->end_pending || d->stop) {
		*ul = 1;
		return;
	}
	*ul = stream_avail(d->in);
	if (*ul == 0 && stream_eof(d->in))
		*ul = 1; /* end of stream: emit the end marker */
}

static void emit_end_block(struct decode *d)
{
	struct gc_block *b = ring_slot(d->out);

	if (!b)
		return;
	memset(b, 0, sizeof(*b));
	b->kind = GC_END;
	b->line = d->lineno;
	ring_commit(d->out);
	d->end_pending = false;
	d->end_sent = true;
}

/* The end of what is executed: the end marker goes out next, and the rest
 * of the input is discarded. */
static void stop_here(struct decode *d)
{
	d->stop = true;
	d->end_pending = true;
}

/* After the end marker: drop the rest of the input (after M2 / error). */
static void discard_rest(struct decode *d)
{
	if (d->stop && stream_avail(d->in)) {
		uint64_t before = stream_lines_taken(d->in);
		stream_discard(d->in);
		uint64_t after = stream_lines_taken(d->in);
		atomic_fetch_add(&d->n_ignored, after - before);
	}
}

/* Decodes the line in linebuf (n characters, or 2: too long) into the slot
 * b; returns the number of blocks committed (0 or 1). */
static uint64_t decode_line(struct decode *d, struct gc_block *b, int r,
			    size_t n)
{
	struct motion_error e;

	if (r == 2) {
		pipeline_fail(d->m, MOTION_E_LINE_TOO_LONG, d->lineno,
			      MOTION_MAX_LINE + 1u,
			      "line longer than %d characters", MOTION_MAX_LINE);
		stop_here(d);
		return 0;
	}
	if (gc_line(&d->gc, d->linebuf, n, d->lineno, b, &e)) {
		pipeline_record(d->m, &e);
		stop_here(d);
		return 0;
	}
	uint64_t blocks = 0;
	if (b->kind != GC_NONE) {
		ring_commit(d->out);
		blocks = 1;
	}
	if (d->gc.ended) /* M2 / M30: the rest is not executed */
		stop_here(d);
	return blocks;
}

uint32_t decode_run(void *arg, unsigned worker)
{
	struct decode *d = arg;
	uint32_t done = 0;
	uint64_t lines = 0, blocks = 0;
	size_t n;

	(void)worker;
	atomic_store(&d->busy, true);
	while (done < d->batch) {
		if (d->end_sent) {
			discard_rest(d);
			break;
		}
		if (d->end_pending) {
			emit_end_block(d);
			if (d->end_pending)
				break;
			done++;
			continue;
		}
		if (pipeline_faulted(d->m)) {
			stop_here(d);
			continue;
		}
		struct gc_block *b = ring_slot(d->out);
		if (!b)
			break;
		int r = stream_next_line(d->in, d->linebuf, &n);
		if (r == 0) {
			if (stream_eof(d->in))
				d->end_pending = true;
			if (!d->end_pending)
				break;
			continue;
		}
		d->lineno++;
		lines++;
		done++;
		blocks += decode_line(d, b, r, n);
	}
	atomic_fetch_add_explicit(&d->n_lines, lines, memory_order_relaxed);
	atomic_fetch_add_explicit(&d->n_blocks, blocks, memory_order_relaxed);
	atomic_store(&d->busy, false);
	return done;
}
