/* SPDX-License-Identifier: MIT */
/*
 * The profile lanes, data-parallel: L lanes (config.interp_lanes, the same
 * count as the interpolation lanes), each a task of its own with an input
 * ring of planned segments (struct planned, from the look-ahead) and an
 * output ring of the same with their peak speeds (to accel).
 *
 * Once the look-ahead has fixed a segment's entry and exit speeds, its
 * peak speed (plan_peak(): for S-curves a Newton iteration, the costliest
 * step of planning) depends on that segment alone.  The look-ahead deals
 * the planned segments in chunks of config.batch, chunk c to lane c mod
 * L; a lane sets each one's peak speed (struct planned, vp); accel takes
 * them back in the same order, chunk by chunk, and is left with the
 * timed profile (plan_profile(), a few square roots) and the serial part
 * (the sample times).  A lane calls the same function on the same inputs
 * as accel did before the lanes, so the setpoints are the same bits
 * whatever the number of lanes or workers.  Every ring stays single-producer
 * single-consumer (the look-ahead, one lane, accel), and no lane runs on
 * two cores at once (rule 1): two lanes are two tasks.
 */
#ifndef SERVOAMP_MOTION_PEAK_H
#define SERVOAMP_MOTION_PEAK_H

#include <stdbool.h>
#include <stdint.h>

#include "items.h"
#include "motion/motion.h"
#include "motion/ring.h"

#define PEAK_MAX_LANES MOTION_MAX_WORKERS

struct peak_lane {
	struct ring in;  /* struct planned: producer the look-ahead */
	struct ring out; /* struct planned, vp set: consumer accel */
	/* wiring, read-only after peaks_init() */
	const struct ring *segs;
	uint32_t batch;
	bool jerk;
};

struct peaks {
	/* wiring, read-only after peaks_init() */
	uint32_t lanes, chunk;
	/* the look-ahead's cursor: the lane it deals to, items in its chunk */
	_Alignas(RING_CACHELINE) uint32_t put_lane, put_fill;
	/* accel's cursor: the lane it takes from, items of its chunk taken */
	_Alignas(RING_CACHELINE) uint32_t get_lane, get_fill;
	_Alignas(RING_CACHELINE) struct peak_lane lane[PEAK_MAX_LANES];
};

/* Setup: allocates the lanes' rings (cap items each, in and out). */
int peaks_init(struct peaks *pk, const struct motion_config *cfg,
	       const struct ring *segs, uint32_t cap);
void peaks_free(struct peaks *pk);

/* The look-ahead's side: the slot for the next planned segment (NULL when
 * its lane's ring is full), then commit it; the ring it deals to now;
 * whether the last commit completed a chunk (or none was made yet). */
struct planned *peaks_slot(struct peaks *pk);
void peaks_commit(struct peaks *pk);
const struct ring *peaks_put_ring(const struct peaks *pk);
bool peaks_put_chunk_done(const struct peaks *pk);

/* Accel's side: the next segment with its peak speed, in planning order
 * (NULL when it is not out of its lane yet), then release it; how many are
 * ready in the lane it takes from; whether the last release completed a
 * chunk. */
const struct planned *peaks_front(struct peaks *pk);
void peaks_release(struct peaks *pk);
uint32_t peaks_ready(const struct peaks *pk);
bool peaks_get_chunk_done(const struct peaks *pk);

/* Scheduler task, one per lane (arg: struct peak_lane). */
void peak_levels(void *arg, uint32_t *ul, uint32_t *dl, uint32_t *dcap);
uint32_t peak_run(void *arg, unsigned worker);

/* The lanes' rings as one queue (planned segments, with or without their
 * peak speeds): items,
 * capacity, peak occupancy (sums over the lanes).  peaks_count() reads the
 * input rings before the output rings: an item moves from one to the
 * other, so a count of 0 means none was in either. */
uint32_t peaks_count(const struct peaks *pk);
uint32_t peaks_cap(const struct peaks *pk);
uint32_t peaks_peak(const struct peaks *pk);

#endif
