/* SPDX-License-Identifier: MIT */
/*
 * The items that travel between the pipeline's stages, one ring each:
 *
 *   stream bytes -> decode -> struct gc_block (gcode.h)
 *                -> fit    -> struct seg
 *                -> look-ahead -> struct planned (one ring per peak lane)
 *                -> peak   -> struct planned with vp (one ring per lane, read
 *                             in chunk order)
 *                -> accel  -> struct piece (one ring per interpolation lane)
 *                -> interp -> compact setpoint (int32 words, below; one
 *                             ring per lane, read in chunk order)
 *                -> motion_next_setpoint(): struct motion_setpoint
 */
#ifndef SERVOAMP_MOTION_ITEMS_H
#define SERVOAMP_MOTION_ITEMS_H

#include <math.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "motion/motion.h"
#include "motion/ring.h"

enum seg_kind { SEG_MOVE = 1, SEG_DWELL, SEG_END };

/* A straight segment (output of curve fitting), sized by the number of
 * axes: x[] holds p0[n], p1[n] and u[n] (n = config.n_axes; the other
 * axes never move, so they are not stored).  A segment is written once,
 * by the fitter, into a slot of the segment ring, and the later stages
 * refer to that slot by its index instead of copying the geometry along
 * the chain: the ring's storage is larger than its capacity (see
 * motion_create), so a slot is not reused before interpolation is done
 * with it. */
struct seg {
	uint8_t kind;
	uint32_t line;
	double len;   /* mm */
	double vmax;  /* path speed cap: feed, axis velocities, len / period */
	double amax;  /* path acceleration: (1 - share) of the axis budgets */
	double jmax;  /* path jerk (jerk-limited mode) */
	double dwell; /* s */
	double x[];   /* p0[n], p1[n], u[n] */
};

#define SEG_P0(s, n) ((s)->x)
#define SEG_P1(s, n) ((s)->x + (n))
#define SEG_U(s, n) ((s)->x + 2 * (n))

static inline size_t seg_size(uint32_t n_axes)
{
	return sizeof(struct seg) + 3u * n_axes * sizeof(double);
}

/* A segment by its position in the segment ring (see struct seg). */
static inline const struct seg *seg_at(const struct ring *segs, uint32_t pos)
{
	return ring_at(segs, pos);
}

/* A segment with its planned entry and exit speeds (look-ahead output)
 * and its peak speed (set by a profile lane: peak.h): the segment by
 * reference (slot index in the segment ring). */
struct planned {
	uint32_t seg;
	uint8_t kind;
	double v0, v1, vp;
};

/* Setpoints travel through their ring compactly, sized by the number of
 * axes n: int32 line, flags (SP_CHUNK_END: the last of its chunk; the
 * consumer reads the next lane after it), pos[n], vel[n] (status MOVING,
 * cycle assigned by the consumer).  sp_unpack() makes the public struct
 * motion_setpoint. */
#define SP_CHUNK_END 1

static inline size_t sp_size(uint32_t n_axes)
{
	return (2u + 2u * n_axes) * sizeof(int32_t);
}

static inline void sp_unpack(uint32_t n, const int32_t *c,
			     struct motion_setpoint *sp)
{
	memset(sp, 0, sizeof(*sp));
	sp->n_axes = (uint8_t)n;
	sp->line = (uint32_t)c[0];
	sp->status = MOTION_ST_MOVING;
	memcpy(sp->pos, c + 2, n * sizeof(int32_t));
	memcpy(sp->vel, c + 2 + n, n * sizeof(int32_t));
}

/* One step of motion_setpoint_hash() over a compact setpoint's words
 * (line, pos[n], vel[n]; FNV-1a over 32-bit words). */
static inline uint64_t sp_hash(uint64_t h, uint32_t n, const int32_t *c)
{
	const uint64_t prime = 1099511628211ull;

	if (h == 0)
		h = 14695981039346656037ull;
	h = (h ^ (uint32_t)c[0]) * prime;
	for (uint32_t k = 0; k < 2 * n; k++)
		h = (h ^ (uint32_t)c[2 + k]) * prime;
	return h;
}

/* Millimetres (or mm/s) times increments per mm to int32 increments,
 * rounded to nearest and saturated. */
static inline int32_t to_inc(double v)
{
	double r = nearbyint(v);
	if (r != r)
		return 0; /* not reached: positions are finite */
	if (r > 2147483647.0)
		return INT32_MAX;
	if (r < -2147483648.0)
		return INT32_MIN;
	return (int32_t)r;
}

#endif
