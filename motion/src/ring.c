/* SPDX-License-Identifier: MIT */
#include "motion/ring.h"

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

int ring_init(struct ring *r, size_t elem, uint32_t cap)
{
	return ring_init_slots(r, elem, cap, cap);
}

int ring_init_slots(struct ring *r, size_t elem, uint32_t cap, uint32_t slots)
{
	uint32_t size = 1;

	memset(r, 0, sizeof(*r));
	if (elem == 0 || cap == 0 || cap > (1u << 30) || slots > (1u << 30))
		return -1;
	if (slots < cap)
		slots = cap;
	while (size < slots)
		size <<= 1;
	size_t stride = elem;
	if (elem > RING_CACHELINE / 2)
		stride = (elem + RING_CACHELINE - 1) / RING_CACHELINE * RING_CACHELINE;
	if ((size_t)size > (SIZE_MAX - RING_CACHELINE) / stride)
		return -1;
	r->buf = aligned_alloc(RING_CACHELINE,
			       ((size_t)size * stride + RING_CACHELINE - 1) /
				       RING_CACHELINE * RING_CACHELINE);
	if (!r->buf)
		return -1;
	memset(r->buf, 0, (size_t)size * stride);
	r->elem = elem;
	r->stride = stride;
	r->cap = cap;
	r->mask = size - 1u;
	atomic_init(&r->head, 0u);
	atomic_init(&r->tail, 0u);
	atomic_init(&r->peak, 0u);
	return 0;
}

void ring_free(struct ring *r)
{
	free(r->buf);
	r->buf = NULL;
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
