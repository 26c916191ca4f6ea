/* SPDX-License-Identifier: MIT */
/* The profile lanes (see peak.h). */
#include "peak.h"

#include "plan.h"

int peaks_init(struct peaks *pk, const struct motion_config *cfg,
	       const struct ring *segs, uint32_t cap)
{
	pk->lanes = cfg->interp_lanes;
	pk->chunk = cfg->batch;
	for (uint32_t k = 0; k < pk->lanes; k++) {
		struct peak_lane *l = &pk->lane[k];
		l->segs = segs;
		l->batch = cfg->batch;
		l->jerk = cfg->jerk_limited;
		if (ring_init(&l->in, sizeof(struct planned), cap) ||
		    ring_init(&l->out, sizeof(struct planned), cap))
			return -1;
	}
	return 0;
}

void peaks_free(struct peaks *pk)
{
	for (uint32_t k = 0; k < PEAK_MAX_LANES; k++) {
		ring_free(&pk->lane[k].in);
		ring_free(&pk->lane[k].out);
	}
}

/* The next lane after a whole chunk. */
static void next_lane(const struct peaks *pk, uint32_t *lane, uint32_t *fill)
{
	if (++*fill < pk->chunk)
		return;
	*fill = 0;
	*lane = *lane + 1 < pk->lanes ? *lane + 1 : 0;
}

struct planned *peaks_slot(struct peaks *pk)
{
	return ring_slot(&pk->lane[pk->put_lane].in);
}

void peaks_commit(struct peaks *pk)
{
	ring_commit(&pk->lane[pk->put_lane].in);
	next_lane(pk, &pk->put_lane, &pk->put_fill);
}

const struct ring *peaks_put_ring(const struct peaks *pk)
{
	return &pk->lane[pk->put_lane].in;
}

bool peaks_put_chunk_done(const struct peaks *pk)
{
	return pk->put_fill == 0;
}

const struct planned *peaks_front(struct peaks *pk)
{
	return ring_front(&pk->lane[pk->get_lane].out);
}

void peaks_release(struct peaks *pk)
{
	ring_release(&pk->lane[pk->get_lane].out);
	next_lane(pk, &pk->get_lane, &pk->get_fill);
}

uint32_t peaks_ready(const struct peaks *pk)
{
	return ring_count(&pk->lane[pk->get_lane].out);
}

bool peaks_get_chunk_done(const struct peaks *pk)
{
	return pk->get_fill == 0;
}

void peak_levels(void *arg, uint32_t *ul, uint32_t *dl, uint32_t *dcap)
{
	struct peak_lane *l = arg;

	*ul = ring_count(&l->in);
	*dl = ring_count(&l->out);
	*dcap = l->out.cap;
}

uint32_t peak_run(void *arg, unsigned worker)
{
	struct peak_lane *l = arg;
	uint32_t done = 0;

	(void)worker;
	while (done < l->batch) {
		const struct planned *in = ring_front(&l->in);
		struct planned *o;
		if (!in || !(o = ring_slot(&l->out)))
			break;
		*o = *in;
		o->vp = in->kind == SEG_MOVE ?
				plan_peak(seg_at(l->segs, in->seg), in->v0, in->v1, l->jerk) :
				0.0;
		ring_commit(&l->out);
		ring_release(&l->in);
		done++;
	}
	return done;
}

uint32_t peaks_count(const struct peaks *pk)
{
	uint32_t n = 0;
	for (uint32_t k = 0; k < pk->lanes; k++)
		n += ring_count(&pk->lane[k].in);
	for (uint32_t k = 0; k < pk->lanes; k++)
		n += ring_count(&pk->lane[k].out);
	return n;
}

uint32_t peaks_cap(const struct peaks *pk)
{
	uint32_t n = 0;
	for (uint32_t k = 0; k < pk->lanes; k++)
		n += pk->lane[k].in.cap + pk->lane[k].out.cap;
	return n;
}

uint32_t peaks_peak(const struct peaks *pk)
{
	uint32_t n = 0;
	for (uint32_t k = 0; k < pk->lanes; k++)
		n += atomic_load(&pk->lane[k].in.peak) +
		     atomic_load(&pk->lane[k].out.peak);
	return n;
}
