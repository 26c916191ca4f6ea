/* SPDX-License-Identifier: MIT */
/* The accel stage (see accel.h). */
#include "accel.h"

#include <string.h>

#include "items.h"
#include "pipeline.h"
#include "plan.h"

void accel_init(struct accel *a, struct motion *m,
		const struct motion_config *cfg, struct peaks *in,
		struct interp *ip, const struct ring *segs)
{
	a->m = m;
	a->in = in;
	a->ip = ip;
	a->segs = segs;
	a->batch = cfg->batch;
	a->na = cfg->n_axes;
	a->lanes = cfg->interp_lanes;
	a->chunk = cfg->interp_chunk ? cfg->interp_chunk : cfg->batch;
	a->T = cfg->period_us * 1e-6;
	a->jerk = cfg->jerk_limited;
	a->tau = a->T;
}

/* At rest past the end of the current segment, with no next one planned:
 * a sample at rest now, or wait for the next segment. */
static bool rest_ready(const struct accel *a)
{
	return a->cur_valid && a->tau > a->dur && a->v1 <= 1e-9 &&
	       peaks_ready(a->in) == 0 && pipeline_rest_now(a->m);
}

void accel_levels(void *arg, uint32_t *ul, uint32_t *dl, uint32_t *dcap)
{
	struct accel *a = arg;
	const struct ring *out = &a->ip->lane[a->lane].in;

	*ul = peaks_ready(a->in);
	if (a->cur_valid && a->tau <= a->dur)
		*ul += 1; /* samples of the current segment still to deal */
	else if (rest_ready(a))
		*ul += 1;
	*dl = ring_count(out);
	*dcap = out->cap;
}

/* Makes the planned segment at the front of the profile lanes the current
 * one: the profile from its three speeds (the peak speed from its lane) and
 * its duration; then releases it.  true when it was the last of its
 * chunk. */
static bool take(struct accel *a, const struct planned *in)
{
	a->seg = in->seg;
	a->kind = in->kind;
	a->v1 = in->v1;
	plan_profile(&a->prof, seg_at(a->segs, in->seg), in->v0, in->vp, in->v1,
		     a->jerk);
	a->dur = a->prof.dur;
	a->cur_valid = true;
	peaks_release(a->in);
	return peaks_get_chunk_done(a->in);
}

/* One piece into the current lane: the samples of the current segment
 * that fit in the current chunk (at_end: the sample at rest instead).
 * false when the lane's ring is full. */
static bool deal(struct accel *a, bool at_end)
{
	struct ring *r = &a->ip->lane[a->lane].in;
	struct piece *pc = ring_slot(r);
	uint32_t n = 0, room = a->chunk - a->fill;

	if (!pc)
		return false;
	memcpy(piece_seg(pc), seg_at(a->segs, a->seg), seg_size(a->na));
	pc->prof = a->prof;
	pc->tau0 = a->tau;
	if (at_end) {
		n = 1;
		pc->n = 0;
		pc->flags = PIECE_AT_END;
	} else {
		/* the serial chain of sample times: the lane repeats it */
		while (a->tau <= a->dur && n < room) {
			a->tau += a->T;
			n++;
		}
		pc->n = n;
		pc->flags = 0;
	}
	a->fill += n;
	if (a->fill >= a->chunk)
		pc->flags |= PIECE_CHUNK_END;
	ring_commit(r);
	/* accel is the only writer: a plain store, no locked add */
	uint64_t is = atomic_load_explicit(&a->issued[a->lane], memory_order_relaxed);
	atomic_store_explicit(&a->issued[a->lane], is + n, memory_order_release);
	if (a->fill >= a->chunk) {
		a->fill = 0;
		a->lane = a->lane + 1 < a->lanes ? a->lane + 1 : 0;
	}
	return true;
}

uint32_t accel_run(void *arg, unsigned worker)
{
	struct accel *a = arg;
	struct interp *ip = a->ip;
	uint32_t done = 0, taken = 0;

	/* up to 2 * batch steps (a segment taken, a piece dealt), ending
	 * after the last segment of a chunk of the profile lanes */
	(void)worker;
	while (done < 2 * a->batch) {
		if (a->cur_valid && a->tau <= a->dur) {
			if (!deal(a, false))
				break;
			done++;
			continue;
		}
		const struct planned *in = peaks_front(a->in);
		if (a->cur_valid) {
			/* past the end of the current segment */
			if (in && in->kind != SEG_END) {
				a->tau -= a->dur;
				bool chunk_end = take(a, in);
				done++;
				taken++;
				if (chunk_end)
					break;
				continue;
			}
			if (a->v1 > 1e-9)
				break; /* moving: wait for the next segment */
			if (!in && !pipeline_rest_now(a->m))
				break; /* at rest: the next one is on its way */
			if (!deal(a, true))
				break;
			a->cur_valid = false;
			a->tau = a->T;
			done++;
			continue;
		}
		if (!in)
			break;
		if (in->kind == SEG_END) {
			peaks_release(a->in);
			atomic_store(&ip->done, true);
			pipeline_notify_end(a->m);
			done++;
			taken++;
			continue;
		}
		atomic_store(&ip->done, false);
		atomic_fetch_add(&ip->active, 1);
		a->tau = a->T;
		bool chunk_end = take(a, in);
		done++;
		taken++;
		if (chunk_end)
			break;
	}
	atomic_fetch_add_explicit(&a->n_profiles, taken, memory_order_relaxed);
	return done;
}
