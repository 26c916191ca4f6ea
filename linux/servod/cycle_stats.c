// SPDX-License-Identifier: MIT
/* cycle_stats.c - servod's counters (cycle_stats.h). */
#define _GNU_SOURCE
#include <stddef.h>
#include <stdio.h>

#include "context.h"

const uint32_t lat_bucket_edges_us[LAT_BUCKETS - 1] = { 10, 20, 50, 100, 200, 300, 500, 1000, 2000 };

static const struct {
	const char *name;
	size_t off;
} published[CYCLE_STATS_PUBLISHED] = {
	{ "servod.wakes", offsetof(struct cycle_stats, wakes) },
	{ "servod.cycles", offsetof(struct cycle_stats, cycles) },
	{ "servod.exchanges", offsetof(struct cycle_stats, exchanges) },
	{ "servod.absent", offsetof(struct cycle_stats, absent) },
	{ "servod.missed_irq", offsetof(struct cycle_stats, missed_irq) },
	{ "servod.late", offsetof(struct cycle_stats, late) },
	{ "servod.stalls", offsetof(struct cycle_stats, stalls) },
	{ "servod.recoveries", offsetof(struct cycle_stats, recoveries) },
	{ "servod.restores", offsetof(struct cycle_stats, restores) },
};

void cycle_stats_wake(struct cycle_stats *s, const struct cycle_wake *w, uint32_t period_ns)
{
	uint64_t event = w->t_ns - w->lat_ns;
	int b = 0;

	s->wakes++;
	if (s->have_count && w->count - s->last_count > 1u)
		s->uio_skips += w->count - s->last_count - 1u;
	s->last_count = w->count;
	s->have_count = 1;
	/* missed interval events: between the events' own times (wake-up
	 * minus the latency read from the counter), not between wake-ups.
	 * An event time that goes back (a latency read across a counter
	 * restart: a wake-up more than a period late, a new period) misses
	 * nothing: the unsigned difference would be ~2^64 / period. */
	if (s->last_event_ns && period_ns && event > s->last_event_ns) {
		uint64_t n = (event - s->last_event_ns + period_ns / 2u) / period_ns;

		if (n > 1u)
			s->missed_irq += n - 1u;
	}
	s->last_event_ns = event;
	if (w->lat_ns < s->lat_min || !s->lat_n)
		s->lat_min = w->lat_ns;
	if (w->lat_ns > s->lat_max)
		s->lat_max = w->lat_ns;
	s->lat_sum += w->lat_ns;
	s->lat_n++;
	while (b < LAT_BUCKETS - 1 && w->lat_ns >= lat_bucket_edges_us[b] * 1000u)
		b++;
	s->lat_hist[b]++;
}

void cycle_stats_heartbeat(struct cycle_stats *s, uint32_t hb, uint64_t t_ns)
{
	if (hb != s->last_hb || !s->last_hb_ns) {
		s->last_hb = hb;
		s->last_hb_ns = t_ns;
		s->last_hb_cycle = s->cycles;
	}
}

void cycle_stats_work(struct cycle_stats *s, uint32_t lat_ns, uint32_t work_ns, uint32_t period_ns)
{
	if (work_ns > s->work_max)
		s->work_max = work_ns;
	s->work_sum += work_ns;
	if ((uint64_t)lat_ns + work_ns > period_ns / 2u)
		s->late++;
}

int cycle_stats_stall(struct cycle_stats *s, uint32_t attach_count, uint64_t t_ns)
{
	if (s->stall_attach == attach_count)
		return 0;
	s->stall_attach = attach_count;
	s->stalls++;
	s->stall_cycles = (uint32_t)(s->cycles - s->last_hb_cycle);
	s->stall_us = (uint32_t)((t_ns - s->last_hb_ns) / 1000u);
	s->stall_cycle = s->cycles;
	return 1;
}

int cycle_stats_peer_error(struct cycle_stats *s, int rc, uint32_t limit, uint32_t attach_count, uint64_t t_ns)
{
	if (rc != AMP_E_PEER_ERROR) {
		s->peer_err_run = 0;
		return 0;
	}
	s->peer_errors++;
	if (s->peer_err_run < UINT32_MAX)
		s->peer_err_run++;
	if (s->peer_err_run < (limit ? limit : 1u))
		return 0;
	return cycle_stats_stall(s, attach_count, t_ns);
}

void cycle_stats_new_session(struct cycle_stats *s)
{
	s->stall_attach = UINT32_MAX;
}

/* A seqcount of seq_cst accesses only (telem_cfg.app_seq): odd before any
 * change, even after them all. */
void cycle_stats_begin(struct cycle_stats_pub *p)
{
	atomic_store(&p->seq, atomic_load_explicit(&p->seq, memory_order_relaxed) + 1u);
}

void cycle_stats_end(const struct cycle_stats *s, struct cycle_stats_pub *p)
{
	for (unsigned i = 0; i < CYCLE_STATS_PUBLISHED; i++)
		atomic_store(&p->v[i], *(const uint64_t *)((const char *)s + published[i].off));
	atomic_store(&p->seq, atomic_load_explicit(&p->seq, memory_order_relaxed) + 1u);
}

void cycle_stats_publish(const struct cycle_stats *s, struct cycle_stats_pub *p)
{
	cycle_stats_begin(p);
	cycle_stats_end(s, p);
}

uint64_t cycle_stats_seq(void *pub)
{
	struct cycle_stats_pub *p = pub;

	return atomic_load(&p->seq);
}

unsigned cycle_stats_counters(void *pub, struct telem_counter *out, unsigned max)
{
	struct cycle_stats_pub *p = pub;
	unsigned n = 0;

	for (; n < max && n < CYCLE_STATS_PUBLISHED; n++) {
		snprintf(out[n].name, sizeof(out[n].name), "%s", published[n].name);
		out[n].value = atomic_load(&p->v[n]);
	}
	return n;
}
