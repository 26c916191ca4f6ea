/* SPDX-License-Identifier: MIT */
#include "motion/ring.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

int ring_init(struct ring *r, size_t elem, uint32_t cap)
{
	return ring_init_slots(r, elem, cap, cap);
}

/* Storage size for `slots` items (a power of two), or 0 if out of range. */
static uint32_t ring_size(size_t elem, uint32_t cap, uint32_t slots)
{
	uint32_t size = 1;

	if (elem == 0 || cap == 0 || cap > (1u << 30) || slots > (1u << 30))
		return 0;
	if (slots < cap)
		slots = cap;
	while (size < slots)
		size <<= 1;
	if ((size_t)size > (SIZE_MAX - RING_CACHELINE) / RING_STRIDE(elem))
		return 0;
	return size;
}

static void ring_setup(struct ring *r, void *buf, size_t elem, uint32_t cap, uint32_t size, bool owned)
{
	r->buf = buf;
	memset(r->buf, 0, RING_BUF_BYTES(elem, size));
	r->elem = elem;
	r->stride = RING_STRIDE(elem);
	r->cap = cap;
	r->mask = size - 1u;
	r->owned = owned;
	ring_reset(r);
}

int ring_init_slots(struct ring *r, size_t elem, uint32_t cap, uint32_t slots)
{
	uint32_t size = ring_size(elem, cap, slots);
	void *buf;

	memset(r, 0, sizeof(*r));
	if (!size)
		return -1;
	buf = aligned_alloc(RING_CACHELINE,
			    (RING_BUF_BYTES(elem, size) + RING_CACHELINE - 1) /
				    RING_CACHELINE * RING_CACHELINE);
	if (!buf)
		return -1;
	ring_setup(r, buf, elem, cap, size, true);
	return 0;
}

int ring_init_buf(struct ring *r, void *buf, size_t bytes, size_t elem, uint32_t cap)
{
	uint32_t size = ring_size(elem, cap, cap);

	memset(r, 0, sizeof(*r));
	if (!size || !buf || (uintptr_t)buf % RING_CACHELINE || bytes < RING_BUF_BYTES(elem, size))
		return -1;
	ring_setup(r, buf, elem, cap, size, false);
	return 0;
}

void ring_free(struct ring *r)
{
	if (r->owned)
		free(r->buf);
	r->buf = NULL;
	r->owned = false;
}

void ring_reset(struct ring *r)
{
	atomic_store(&r->head, 0u);
	atomic_store(&r->tail, 0u);
	atomic_store(&r->peak, 0u);
	r->head_seen = 0;
	r->tail_seen = 0;
}

bool ring_push(struct ring *r, const void *item)
{
	void *slot = ring_slot(r);

	if (!slot)
		return false;
	memcpy(slot, item, r->elem);
	ring_commit(r);
	return true;
}

bool ring_pop(struct ring *r, void *item)
{
	const void *p = ring_front(r);

	if (!p)
		return false;
	memcpy(item, p, r->elem);
	ring_release(r);
	return true;
}
