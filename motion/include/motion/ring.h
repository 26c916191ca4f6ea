/* SPDX-License-Identifier: MIT */
/*
 * Bounded single-producer single-consumer ring buffer of fixed-size items.
 * Rule 1 of the hybrid scheduler (a task never runs on two cores at once)
 * makes every queue of the chain SPSC, so C11 acquire/release atomics are
 * enough.  Storage is allocated once in ring_init().
 */
#ifndef SERVOAMP_MOTION_RING_H
#define SERVOAMP_MOTION_RING_H

#include <stdatomic.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

struct ring {
	unsigned char *buf;
	size_t elem;       /* item size, bytes */
	uint32_t cap;      /* logical capacity, items */
	uint32_t mask;     /* storage size - 1 (power of two >= cap) */
	_Atomic uint32_t head; /* consumer index (free running) */
	_Atomic uint32_t tail; /* producer index (free running) */
	_Atomic uint32_t peak; /* highest occupancy seen (written by producer) */
};

int ring_init(struct ring *r, size_t elem, uint32_t cap);
void ring_free(struct ring *r);

static inline uint32_t ring_count(const struct ring *r)
{
	uint32_t t = atomic_load_explicit(&r->tail, memory_order_acquire);
	uint32_t h = atomic_load_explicit(&r->head, memory_order_acquire);
	return t - h;
}

static inline uint32_t ring_room(const struct ring *r)
{
	return r->cap - ring_count(r);
}

/* Producer: slot for the next item, or NULL when full; then ring_commit(). */
static inline void *ring_slot(struct ring *r)
{
	uint32_t t = atomic_load_explicit(&r->tail, memory_order_relaxed);
	uint32_t h = atomic_load_explicit(&r->head, memory_order_acquire);
	if (t - h >= r->cap)
		return NULL;
	return r->buf + (size_t)(t & r->mask) * r->elem;
}

static inline void ring_commit(struct ring *r)
{
	uint32_t t = atomic_load_explicit(&r->tail, memory_order_relaxed) + 1u;
	atomic_store_explicit(&r->tail, t, memory_order_release);
	uint32_t n = t - atomic_load_explicit(&r->head, memory_order_acquire);
	if (n > atomic_load_explicit(&r->peak, memory_order_relaxed))
		atomic_store_explicit(&r->peak, n, memory_order_relaxed);
}

/* Consumer: oldest item, or NULL when empty; then ring_release(). */
static inline const void *ring_front(struct ring *r)
{
	uint32_t h = atomic_load_explicit(&r->head, memory_order_relaxed);
	uint32_t t = atomic_load_explicit(&r->tail, memory_order_acquire);
	if (t == h)
		return NULL;
	return r->buf + (size_t)(h & r->mask) * r->elem;
}

static inline void ring_release(struct ring *r)
{
	uint32_t h = atomic_load_explicit(&r->head, memory_order_relaxed);
	atomic_store_explicit(&r->head, h + 1u, memory_order_release);
}

bool ring_push(struct ring *r, const void *item);
bool ring_pop(struct ring *r, void *item);

#endif
