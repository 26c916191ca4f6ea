/* SPDX-License-Identifier: MIT */
/* The accel stage (see accel.h). */
#include "accel.h"

#include "items.h"
#include "plan.h"

void accel_init(struct accel *a, const struct motion_config *cfg,
		struct ring *in, struct ring *out, const struct ring *segs)
{
	a->in = in;
	a->out = out;
	a->segs = segs;
	a->batch = cfg->batch;
	a->jerk = cfg->jerk_limited;
}

void accel_levels(void *arg, uint32_t *ul, uint32_t *dl, uint32_t *dcap)
{
	struct accel *a = arg;

	*ul = ring_count(a->in);
	*dl = ring_count(a->out);
	*dcap = a->out->cap;
}

uint32_t accel_run(void *arg, unsigned worker)
{
	struct accel *a = arg;
	uint32_t done = 0;

	(void)worker;
	while (done < a->batch) {
		struct timed *p = ring_slot(a->out);
		const struct planned *in = ring_front(a->in);
		if (!p || !in)
			break;
		p->seg = in->seg;
		p->kind = in->kind;
		p->v0 = in->v0;
		p->v1 = in->v1;
		p->vp = in->kind == SEG_MOVE
				? plan_peak(seg_at(a->segs, in->seg), in->v0,
					    in->v1, a->jerk)
				: 0.0;
		ring_release(a->in);
		ring_commit(a->out);
		done++;
	}
	atomic_fetch_add_explicit(&a->n_profiles, done, memory_order_relaxed);
	return done;
}
