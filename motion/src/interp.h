/* SPDX-License-Identifier: MIT */
/*
 * The interpolation stage, data-parallel: L lanes (config.interp_lanes),
 * each a task of its own with its own input ring of pieces (struct piece,
 * items.h) and its own output ring of compact setpoints.
 *
 * The serial part of interpolation (the sample times: each segment's first
 * sample time carries the time left over from the previous segment, a
 * chain of floating-point additions, and the choice between going on into
 * the next segment and stopping at rest) is done by the accel stage
 * (accel.h), which cuts the sample stream into chunks of
 * config.interp_chunk setpoints and deals chunk c to lane c mod L.  A
 * piece is the part of one segment that falls into one chunk: its first
 * sample time, its number of samples and the segment's three speeds.  A
 * lane expands the segment's profile (plan_profile()) and samples it: the
 * same function on the same inputs as the serial interpolator, so the
 * setpoints are the same bits whatever the number of lanes or workers.
 * The last setpoint of a chunk carries SP_CHUNK_END; the consumer
 * (cycle.c) reads the lanes in chunk order and moves to the next lane
 * after it.  Every ring stays single-producer single-consumer, and no lane
 * runs on two cores at once (rule 1 holds): two lanes are two tasks.
 */
#ifndef SERVOAMP_MOTION_INTERP_H
#define SERVOAMP_MOTION_INTERP_H

#include <stdatomic.h>
#include <stdbool.h>
#include <stdint.h>

#include "motion/motion.h"
#include "motion/ring.h"
#include "items.h"
#include "plan.h"

#define INTERP_MAX_LANES MOTION_MAX_WORKERS

/* Interpolation input (accel -> one interpolation lane, see interp.h):
 * the part of one segment that falls into one chunk of setpoints.  The
 * lane samples the profile that accel expanded: n samples at
 * tau0, tau0 + T, ... (each by adding T to the previous one, as the
 * serial interpolator did), then, with PIECE_AT_END, one sample exactly at
 * the end point.  PIECE_CHUNK_END: its last sample ends the chunk.
 *
 * The piece carries a copy of its segment (piece_seg(), seg_size() bytes
 * after the header) rather than its slot: lanes work behind one another
 * by up to a whole output ring of setpoints, and a segment that yields no
 * sample (shorter than the time left over) yields no piece, so the lanes
 * cannot bound how long a segment slot would have to stay valid.  Accel
 * is the segment's last reader, as the serial interpolator was. */
enum { PIECE_AT_END = 1, PIECE_CHUNK_END = 2 };

struct piece {
	uint32_t n;
	uint8_t flags;
	double tau0;
	struct profile prof; /* expanded once, by accel */
	/* then struct seg, seg_size(n_axes) bytes */
};

static inline size_t piece_size(uint32_t n_axes)
{
	return sizeof(struct piece) + seg_size(n_axes);
}

static inline struct seg *piece_seg(void *pc)
{
	return (struct seg *)((unsigned char *)pc + sizeof(struct piece));
}


struct interp;

struct interp_lane {
	/* producer side of in: the accel stage; consumer side of out: the
	 * consumer (cycle.c) */
	struct ring in;  /* struct piece */
	struct ring out; /* compact setpoints */
	/* wiring, read-only after interp_init() */
	struct interp *ip;
	const _Atomic uint64_t *issued; /* samples dealt to this lane (accel) */
	unsigned id;
	/* state: the piece at the front of in, as far as it is done */
	_Alignas(RING_CACHELINE) const struct seg *g;
	double tau;
	uint32_t i;            /* samples of the piece done */
	bool have;             /* prof, g, tau, i are the front piece's */
	_Atomic uint64_t produced; /* samples produced (per job) */
};

struct interp {
	/* wiring, read-only after interp_init() */
	struct motion *m;         /* for pipeline_notify_end() */
	const struct ring *segs;  /* the segment ring (pieces carry copies) */
	uint32_t na, batch, lanes;
	double T;                 /* period, s */
	double ipm;               /* increments per mm */
	bool jerk;
	/* shared state: set by accel, lanes and the consumer */
	_Alignas(RING_CACHELINE) atomic_bool done; /* the end marker has passed */
	atomic_int active;        /* motions started and not yet at rest */
	_Alignas(RING_CACHELINE) struct interp_lane lane[INTERP_MAX_LANES];
};

/* Setup: allocates the lanes' rings (lane_in, lane_out items each). */
int interp_init(struct interp *ip, struct motion *m,
		const struct motion_config *cfg, const struct ring *segs,
		const _Atomic uint64_t *issued, uint32_t lane_in,
		uint32_t lane_out);
void interp_free(struct interp *ip);

/* Scheduler task, one per lane (arg: struct interp_lane). */
void interp_levels(void *arg, uint32_t *ul, uint32_t *dl, uint32_t *dcap);
uint32_t interp_run(void *arg, unsigned worker);

/* The lanes' rings as one queue: items, capacity, peak (sum over lanes). */
uint32_t interp_in_count(const struct interp *ip);
uint32_t interp_out_count(const struct interp *ip);
uint32_t interp_in_cap(const struct interp *ip);
uint32_t interp_out_cap(const struct interp *ip);
uint32_t interp_in_peak(const struct interp *ip);
uint32_t interp_out_peak(const struct interp *ip);
/* Every piece dealt so far is sampled and every setpoint taken. */
bool interp_drained(const struct interp *ip);

#ifdef MOTION_TEST_HOOKS
/* Tests only (interp.c): called by a lane just before it releases a piece
 * whose setpoints are all committed. */
extern void (*interp_test_release_hook)(const struct interp_lane *l,
					const struct piece *pc);
#endif

/* One setpoint of segment g (profile p) at time tau into it, or exactly at
 * its end point (at_end); sp has sp_size() bytes. */
void interp_sample(const struct interp *ip, int32_t *sp,
		   const struct profile *p, const struct seg *g, double tau,
		   bool at_end);

#endif
