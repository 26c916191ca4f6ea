/* SPDX-License-Identifier: MIT */
/*
 * setpoint_queue.h - the program's setpoints from the feeder thread (the
 * one producer) to the cycle thread (the one consumer): a lock-free SPSC
 * queue of SPQ_N motion setpoints in the runner's own storage. The cycle
 * thread peeks and drops (it looks at the next setpoint before it takes
 * it); it never blocks, never allocates, never makes a syscall.
 */
#ifndef SERVOD_SETPOINT_QUEUE_H
#define SERVOD_SETPOINT_QUEUE_H

#include <stdatomic.h>
#include <stdint.h>

#include "motion/motion.h"

#define SPQ_N 1024u		/* setpoints buffered ahead (1.02 s at 1 ms) */

struct setpoint_queue {
	struct motion_setpoint slot[SPQ_N];
	_Atomic uint32_t head, tail;	/* head: consumer, tail: producer */
};

/* Empty it; only while neither side uses it. */
static inline void spq_reset(struct setpoint_queue *q)
{
	atomic_store(&q->head, 0);
	atomic_store(&q->tail, 0);
}

static inline uint32_t spq_count(struct setpoint_queue *q)
{
	return atomic_load_explicit(&q->tail, memory_order_acquire) -
	       atomic_load_explicit(&q->head, memory_order_acquire);
}

static inline uint32_t spq_room(struct setpoint_queue *q)
{
	return SPQ_N - spq_count(q);
}

/* Consumer: the oldest setpoint, or NULL when empty; then spq_drop(). */
static inline const struct motion_setpoint *spq_peek(struct setpoint_queue *q)
{
	uint32_t h = atomic_load_explicit(&q->head, memory_order_relaxed);

	if (atomic_load_explicit(&q->tail, memory_order_acquire) == h)
		return 0;
	return &q->slot[h % SPQ_N];
}

static inline void spq_drop(struct setpoint_queue *q)
{
	atomic_store_explicit(&q->head, atomic_load_explicit(&q->head, memory_order_relaxed) + 1u,
			      memory_order_release);
}

/* Producer: appends sp; the caller checked spq_room(). */
static inline void spq_push(struct setpoint_queue *q, const struct motion_setpoint *sp)
{
	uint32_t t = atomic_load_explicit(&q->tail, memory_order_relaxed);

	q->slot[t % SPQ_N] = *sp;
	atomic_store_explicit(&q->tail, t + 1u, memory_order_release);
}

#endif
