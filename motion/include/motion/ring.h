/* SPDX-License-Identifier: MIT */
/*
 * Bounded single-producer single-consumer ring buffer of fixed-size items.
 * Rule 1 of the hybrid scheduler (a task never runs on two cores at once)
 * makes every queue of the chain SPSC, so C11 acquire/release atomics are
 * enough.
 *
 * The one SPSC ring of the repository: the motion pipeline's queues,
 * servod's setpoint queue (program runner to cycle thread) and the
 * telemetry transport's cycle records (cycle thread to drain thread) all
 * use it.  Storage is allocated by ring_init() or given by the caller
 * (ring_init_buf(), no allocation).
 *
 * Layout for two cores: the producer's index (tail) and the consumer's
 * index (head) live on separate cache lines, and each side keeps a private
 * copy of the other side's index.  A side reads the other side's line only
 * when its copy says the ring is full (producer) or empty (consumer), so a
 * producer and a consumer running at the same time on two cores do not
 * bounce one cache line per item.  The struct is cache-line aligned, so an
 * array of rings shares no line either.
 */
#ifndef SERVOAMP_MOTION_RING_H
#define SERVOAMP_MOTION_RING_H

#include <stdatomic.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#define RING_CACHELINE 64

/* Slot size for items of `elem` bytes: elem, or whole cache lines for items
 * of more than half a line (see struct ring's stride). */
#define RING_STRIDE(elem) \
	((elem) > RING_CACHELINE / 2 ? ((elem) + RING_CACHELINE - 1) / RING_CACHELINE * RING_CACHELINE : (elem))
/* Bytes of caller storage ring_init_buf() needs for `slots` items (`slots`
 * a power of two). */
#define RING_BUF_BYTES(elem, slots) ((size_t)(slots) * RING_STRIDE(elem))

struct ring {
	/* read-only after ring_init() */
	unsigned char *buf;
	size_t elem;       /* item size, bytes */
	size_t stride;     /* slot size: elem, rounded up to whole cache
			      lines for items of more than half a line, so
			      that such an item never shares a line with
			      another (smaller items pack; a 32-byte item
			      takes half a line) */
	uint32_t cap;      /* logical capacity, items */
	uint32_t mask;     /* storage size - 1 (power of two >= cap) */
	bool owned;        /* buf allocated by ring_init(), freed by ring_free() */
	/* producer side */
	_Alignas(RING_CACHELINE) _Atomic uint32_t tail; /* free running */
	uint32_t head_seen; /* producer's copy of head (may lag) */
	_Atomic uint32_t peak; /* highest occupancy seen (written by producer) */
	/* consumer side */
	_Alignas(RING_CACHELINE) _Atomic uint32_t head; /* free running */
	uint32_t tail_seen; /* consumer's copy of tail (may lag) */
};

int ring_init(struct ring *r, size_t elem, uint32_t cap);
/* Like ring_init(), with storage for at least `slots` items (>= cap): an
 * item's slot is then not reused until `slots - cap` further items have
 * been consumed, so a consumer may hand out references to consumed items
 * (ring_front_pos(), ring_at()) that stay valid for that long. */
int ring_init_slots(struct ring *r, size_t elem, uint32_t cap, uint32_t slots);
/* Like ring_init(), in the caller's storage: `buf` aligned to
 * RING_CACHELINE, at least RING_BUF_BYTES(elem, n) bytes where n is cap
 * rounded up to a power of two. -1 if it is not. */
int ring_init_buf(struct ring *r, void *buf, size_t bytes, size_t elem, uint32_t cap);
/* Frees what ring_init() allocated (nothing for ring_init_buf()). */
void ring_free(struct ring *r);
/* Empty it; only while neither side uses it. */
void ring_reset(struct ring *r);

/* Any thread (the scheduler's level functions, statistics). */
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
	if (t - r->head_seen >= r->cap) {
		r->head_seen = atomic_load_explicit(&r->head, memory_order_acquire);
		if (t - r->head_seen >= r->cap)
			return NULL;
	}
	return r->buf + (size_t)(t & r->mask) * r->stride;
}

static inline void ring_commit(struct ring *r)
{
	uint32_t t = atomic_load_explicit(&r->tail, memory_order_relaxed) + 1u;
	atomic_store_explicit(&r->tail, t, memory_order_release);
	/* the occupancy is at most t - head_seen; refresh the copy of head
	 * only when that bound is a new peak, so the peak stays exact (as of
	 * this commit) and the consumer's line is read rarely */
	if (t - r->head_seen > atomic_load_explicit(&r->peak, memory_order_relaxed)) {
		r->head_seen = atomic_load_explicit(&r->head, memory_order_acquire);
		uint32_t n = t - r->head_seen;
		if (n > atomic_load_explicit(&r->peak, memory_order_relaxed))
			atomic_store_explicit(&r->peak, n, memory_order_relaxed);
	}
}

/* Consumer: oldest item, or NULL when empty; then ring_release(). */
static inline const void *ring_front(struct ring *r)
{
	uint32_t h = atomic_load_explicit(&r->head, memory_order_relaxed);
	if (h == r->tail_seen) {
		r->tail_seen = atomic_load_explicit(&r->tail, memory_order_acquire);
		if (h == r->tail_seen)
			return NULL;
	}
	return r->buf + (size_t)(h & r->mask) * r->stride;
}

static inline void ring_release(struct ring *r)
{
	uint32_t h = atomic_load_explicit(&r->head, memory_order_relaxed);
	atomic_store_explicit(&r->head, h + 1u, memory_order_release);
}

/* Consumer: storage position of the item ring_front() returned. */
static inline uint32_t ring_front_pos(const struct ring *r)
{
	return atomic_load_explicit(&r->head, memory_order_relaxed) & r->mask;
}

/* The item at a storage position (see ring_init_slots()). */
static inline void *ring_at(const struct ring *r, uint32_t pos)
{
	return r->buf + (size_t)(pos & r->mask) * r->stride;
}

bool ring_push(struct ring *r, const void *item);
bool ring_pop(struct ring *r, void *item);

#endif
