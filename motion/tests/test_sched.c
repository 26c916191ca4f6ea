/* SPDX-License-Identifier: MIT */
/* Hybrid scheduler: the decision rules (pure function) and the balance
 * experiment of its design (docs/motion.md) run synchronously (150 items upstream, 6 chained tasks). */
#define _POSIX_C_SOURCE 200809L
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "motion/ring.h"
#include "scheduler.h"

static struct sched_dstate D(uint8_t o, uint32_t ul, uint32_t dl, uint32_t cap,
			     bool running)
{
	struct sched_dstate d = { o, ul, dl, cap, running, 0 };
	return d;
}

static int t_periodic_wins(void)
{
	struct sched_pstate p[3] = { { 5, true, false }, { 2, true, false },
				     { 1, false, false } };
	struct sched_dstate d[1] = { D(16, 100, 0, 10, false) };
	struct sched_choice c = sched_decide(MOTION_POLICY_HYBRID, p, 3, d, 1);

	CHECK(c.kind == SCHED_CHOICE_PERIODIC && c.index == 1, "got %d/%d", c.kind, c.index);
	p[1].running = true; /* a running periodic task is not dispatched twice */
	c = sched_decide(MOTION_POLICY_HYBRID, p, 3, d, 1);
	CHECK(c.kind == SCHED_CHOICE_PERIODIC && c.index == 0, "got %d/%d", c.kind, c.index);
	p[0].ready = false;
	c = sched_decide(MOTION_POLICY_HYBRID, p, 3, d, 1);
	CHECK(c.kind == SCHED_CHOICE_DATA && c.index == 0, "data expected");
	c = sched_decide(MOTION_POLICY_FIFO, p, 0, d, 0);
	CHECK(c.kind == SCHED_CHOICE_IDLE && c.index == -1, "idle expected");
	return 0;
}

static int t_rule1_running(void)
{
	struct sched_dstate d[2] = { D(16, 50, 0, 10, true), D(17, 3, 0, 10, false) };
	struct sched_choice c = sched_decide(MOTION_POLICY_HYBRID, NULL, 0, d, 2);

	CHECK(c.kind == SCHED_CHOICE_DATA && c.index == 1, "running task chosen");
	d[1].running = true;
	c = sched_decide(MOTION_POLICY_HYBRID, NULL, 0, d, 2);
	CHECK(c.kind == SCHED_CHOICE_IDLE, "expected idle");
	return 0;
}

static int t_rule2_data_and_room(void)
{
	struct sched_dstate d[3] = { D(16, 0, 0, 10, false),   /* no input */
				     D(17, 40, 10, 10, false), /* output full */
				     D(18, 1, 9, 10, false) };
	struct sched_choice c = sched_decide(MOTION_POLICY_HYBRID, NULL, 0, d, 3);

	CHECK(c.kind == SCHED_CHOICE_DATA && c.index == 2, "got %d/%d", c.kind, c.index);
	d[2].ul = 0;
	c = sched_decide(MOTION_POLICY_HYBRID, NULL, 0, d, 3);
	CHECK(c.kind == SCHED_CHOICE_IDLE, "expected idle");
	return 0;
}

static int t_rule3_largest_difference(void)
{
	struct sched_dstate d[4] = { D(16, 5, 4, 10, false), D(17, 9, 1, 10, false),
				     D(18, 8, 0, 10, false), D(19, 2, 0, 10, false) };
	struct sched_choice c = sched_decide(MOTION_POLICY_HYBRID, NULL, 0, d, 4);

	CHECK(c.kind == SCHED_CHOICE_DATA && c.index == 1, "got index %d, want 1", c.index);
	/* negative differences compare too */
	struct sched_dstate e[2] = { D(16, 2, 9, 10, false), D(17, 1, 5, 10, false) };
	c = sched_decide(MOTION_POLICY_HYBRID, NULL, 0, e, 2);
	CHECK(c.kind == SCHED_CHOICE_DATA && c.index == 1, "got index %d, want 1", c.index);
	return 0;
}

static int t_rule4_tie_upstream(void)
{
	/* array order is not chain order: O decides */
	struct sched_dstate d[3] = { D(20, 6, 2, 10, false), D(17, 5, 1, 10, false),
				     D(18, 4, 0, 10, false) };
	struct sched_choice c = sched_decide(MOTION_POLICY_HYBRID, NULL, 0, d, 3);

	CHECK(c.kind == SCHED_CHOICE_DATA && c.index == 1, "got index %d, want 1", c.index);
	return 0;
}

static int t_fifo_policy(void)
{
	struct sched_dstate d[3] = { D(16, 50, 0, 10, false), D(17, 1, 0, 10, false),
				     D(18, 1, 0, 10, false) };
	d[0].last = 9;
	d[1].last = 7;
	d[2].last = 8;
	struct sched_choice c = sched_decide(MOTION_POLICY_FIFO, NULL, 0, d, 3);
	CHECK(c.kind == SCHED_CHOICE_DATA && c.index == 1, "FIFO picked %d", c.index);
	return 0;
}

/* Reference implementation, written differently (scores), for a
 * randomized comparison. */
static struct sched_choice reference(const struct sched_pstate *p, size_t np,
				     const struct sched_dstate *d, size_t nd)
{
	struct sched_choice c = { SCHED_CHOICE_IDLE, -1 };
	long best = -1;

	for (size_t i = 0; i < np; i++) {
		long score = p[i].ready && !p[i].running ? 1000 - p[i].prio : -1;
		if (score > best) {
			best = score;
			c.kind = SCHED_CHOICE_PERIODIC;
			c.index = (int)i;
		}
	}
	if (c.kind == SCHED_CHOICE_PERIODIC)
		return c;
	long long bs = 0;
	for (size_t i = 0; i < nd; i++) {
		bool ok = !d[i].running && d[i].ul > 0 && d[i].dl < d[i].dcap;
		if (!ok)
			continue;
		/* difference first, then smaller order: one key */
		long long key = ((long long)d[i].ul - (long long)d[i].dl) * 1024 +
				(255 - d[i].order);
		if (c.kind == SCHED_CHOICE_IDLE || key > bs) {
			bs = key;
			c.kind = SCHED_CHOICE_DATA;
			c.index = (int)i;
		}
	}
	return c;
}

/* Linear congruential generator of the randomized tests (reproducible). */
static uint32_t rnd(uint32_t *s, uint32_t n)
{
	*s = *s * 1664525u + 1013904223u;
	return (*s >> 8) % n;
}

/* nd random data-task states at distinct chain positions (16..23, in
 * shuffled array order): capacity 1..cap_max, UL below ul_lim, running one
 * time in run_one_in. */
static void random_dstates(struct sched_dstate *d, size_t nd, uint32_t *s,
			   uint32_t cap_max, uint32_t ul_lim, uint32_t run_one_in)
{
	uint8_t orders[8] = { 16, 17, 18, 19, 20, 21, 22, 23 };

	for (size_t i = 0; i < 8; i++) { /* shuffle chain positions */
		size_t j = rnd(s, 8);
		uint8_t t = orders[i];
		orders[i] = orders[j];
		orders[j] = t;
	}
	for (size_t i = 0; i < nd; i++) {
		d[i].order = orders[i];
		d[i].dcap = 1 + rnd(s, cap_max);
		d[i].ul = rnd(s, ul_lim);
		d[i].dl = rnd(s, d[i].dcap + 1);
		d[i].running = rnd(s, run_one_in) == 0;
		d[i].last = rnd(s, 100);
	}
}

static int t_random_vs_reference(void)
{
	uint32_t s = 2024;
	int mismatches = 0;

#define R(n) rnd(&s, (n))
	for (int it = 0; it < 200000; it++) {
		struct sched_pstate p[3];
		struct sched_dstate d[8];
		size_t np = R(4), nd = R(9);
		for (size_t i = 0; i < np; i++) {
			p[i].prio = (uint8_t)R(4);
			p[i].ready = R(4) == 0;
			p[i].running = R(4) == 0;
		}
		random_dstates(d, nd, &s, 8, 10, 5);
		struct sched_choice a = sched_decide(MOTION_POLICY_HYBRID, p, np, d, nd);
		struct sched_choice b = reference(p, np, d, nd);
		/* equal-priority periodic ties: both take the lowest index */
		if (a.kind != b.kind || a.index != b.index)
			mismatches++;
	}
#undef R
	CHECK(mismatches == 0, "%d decisions differ from the reference", mismatches);
	return 0;
}

/* ---- the balance experiment: 6 chained data tasks, 150 items upstream -- */

#define NT 6
struct chain {
	struct ring q[NT];       /* q[i] is the upstream queue of task i */
	uint32_t delivered, out_of_order, next_seq;
	uint32_t growth[NT];     /* items produced per item consumed */
	uint32_t pending[NT];    /* outputs still to emit for the current item */
	uint32_t cur[NT];
};
struct ctask {
	struct chain *c;
	int i;
};

static void c_levels(void *arg, uint32_t *ul, uint32_t *dl, uint32_t *dcap)
{
	struct ctask *t = arg;
	struct chain *c = t->c;

	*ul = ring_count(&c->q[t->i]) + (c->pending[t->i] ? 1u : 0u);
	if (t->i + 1 < NT) {
		*dl = ring_count(&c->q[t->i + 1]);
		*dcap = c->q[t->i + 1].cap;
	} else { /* the last task hands items to the position sender */
		*dl = 0;
		*dcap = 1;
	}
}

static uint32_t c_run(void *arg, unsigned worker)
{
	struct ctask *t = arg;
	struct chain *c = t->c;
	int i = t->i;

	(void)worker;
	if (!c->pending[i]) {
		if (!ring_pop(&c->q[i], &c->cur[i]))
			return 0;
		c->pending[i] = c->growth[i];
	}
	uint32_t item = c->cur[i];
	if (i + 1 < NT) {
		if (!ring_push(&c->q[i + 1], &item))
			return 0;
	} else {
		/* items keep their order (1:N copies stay together) */
		if (item < c->next_seq || item > c->next_seq + 1)
			c->out_of_order++;
		c->next_seq = item;
		c->delivered++;
	}
	c->pending[i]--;
	return 1;
}

static void c_sample(void *arg, uint32_t *v)
{
	struct chain *c = arg;

	for (int i = 0; i < NT; i++)
		v[i] = ring_count(&c->q[i]);
}

static const char *const qnames[NT] = { "q0", "q1", "q2", "q3", "q4", "q5" };

/* Runs the chain synchronously; returns the largest spread of the task
 * differences (UL - DL) over the steps after warm-up, among the tasks not
 * blocked by a full downstream queue.  One step of the chosen task moves
 * its own difference by -2 and its neighbours' by +1, so a balanced chain
 * keeps a spread of at most 3. */
static int run_chain(enum motion_policy pol, uint32_t cap, const uint32_t *growth,
		     int from,
		     uint32_t *spread_out, uint32_t *delivered, uint32_t *ooo,
		     const char *csv)
{
	struct chain c;
	struct ctask ct[NT];
	struct sched_task_desc td[NT];

	memset(&c, 0, sizeof(c));
	for (int i = 0; i < NT; i++) {
		if (ring_init(&c.q[i], sizeof(uint32_t), i == 0 ? 256 : cap))
			return -1;
		c.growth[i] = growth ? growth[i] : 1;
		ct[i].c = &c;
		ct[i].i = i;
		td[i] = (struct sched_task_desc){ .name = qnames[i],
			.order = (uint8_t)(16 + i), .levels = c_levels, .run = c_run,
			.arg = &ct[i] };
	}
	uint32_t total = 1;
	for (int i = 0; i < NT; i++)
		total *= c.growth[i];
	for (uint32_t k = 0; k < 150; k++)
		ring_push(&c.q[0], &k);
	struct sched *s = sched_create(pol, td, NT, 20000);
	if (!s)
		return -1;
	sched_set_sampler(s, NT, qnames, c_sample, &c);
	uint32_t spread = 0, steps = 0;
	for (;;) {
		struct sched_choice ch = sched_step(s);
		sched_sample(s);
		if (ch.kind == SCHED_CHOICE_IDLE)
			break;
		steps++;
		/* after warm-up (the first item reached the end), and while
		 * the upstream still holds items, compare the differences */
		if (c.delivered == 0 || ring_count(&c.q[0]) == 0)
			continue;
		int64_t lo = INT64_MAX, hi = INT64_MIN;
		for (int i = from; i < NT; i++) {
			uint32_t ul, dl, dc;
			c_levels(&ct[i], &ul, &dl, &dc);
			if (dl >= dc) /* blocked by a full queue (rule 2) */
				continue;
			int64_t d = (int64_t)ul - (int64_t)dl;
			lo = d < lo ? d : lo;
			hi = d > hi ? d : hi;
		}
		if ((uint32_t)(hi - lo) > spread)
			spread = (uint32_t)(hi - lo);
	}
	if (csv) {
		FILE *f = fopen(csv, "w");
		if (f) {
			sched_trace_csv(s, f);
			fclose(f);
		}
	}
	struct sched_stats st;
	sched_get_stats(s, &st);
	printf("  %s cap %u: %u steps, spread %u, delivered %u/%u, runs:",
	       pol == MOTION_POLICY_HYBRID ? "hybrid" : "fifo", cap, steps, spread,
	       c.delivered, 150 * total);
	for (int i = 0; i < NT; i++)
		printf(" %llu", (unsigned long long)st.runs[i][0]);
	printf("\n");
	sched_destroy(s);
	for (int i = 0; i < NT; i++)
		ring_free(&c.q[i]);
	*spread_out = spread;
	*delivered = c.delivered;
	*ooo = c.out_of_order;
	(void)total;
	return 0;
}

static int t_hybrid_balance(void)
{
	uint32_t sh, sf, dh, df, oh, of;
	const char *csv = getenv("SCHED_TRACE_CSV");

	CHECK(run_chain(MOTION_POLICY_HYBRID, 1000, NULL, 0, &sh, &dh, &oh, csv) == 0, "setup");
	CHECK(run_chain(MOTION_POLICY_FIFO, 1000, NULL, 0, &sf, &df, &of, NULL) == 0, "setup");
	CHECK(dh == 150 && df == 150, "delivered %u / %u of 150", dh, df);
	CHECK(oh == 0 && of == 0, "items out of order");
	/* the hybrid rule keeps every UL - DL within a couple of items of
	 * the others; FIFO lets the upstream difference run away */
	CHECK(sh <= 3, "hybrid spread %u", sh);
	CHECK(sf > 20, "FIFO spread only %u (test would not discriminate)", sf);
	return 0;
}

static int t_hybrid_growth_and_caps(void)
{
	/* 1:N growth (curve fitting makes 4 items of each) with small queues */
	static const uint32_t growth[NT] = { 1, 4, 1, 1, 1, 1 };
	uint32_t sh, dh, oh;

	CHECK(run_chain(MOTION_POLICY_HYBRID, 16, growth, 1, &sh, &dh, &oh, getenv("SCHED_TRACE_CSV2")) == 0, "setup");
	CHECK(dh == 600 && oh == 0, "delivered %u of 600, %u out of order", dh, oh);
	/* the 150-item source stays far above the 16-item queues; the
	 * tasks downstream of it keep balanced differences */
	CHECK(sh <= 3, "spread %u with 1:4 growth", sh);
	uint32_t sf, df, of;
	CHECK(run_chain(MOTION_POLICY_FIFO, 16, growth, 1, &sf, &df, &of, NULL) == 0, "setup");
	CHECK(df == 600 && of == 0, "FIFO delivered %u", df);
	CHECK(sf > sh, "FIFO spread %u not above hybrid %u", sf, sh);
	return 0;
}

static bool eligible(const struct sched_dstate *d)
{
	return !d->running && d->ul > 0 && d->dl < d->dcap;
}

/* Whole jobs (sched_gate): explicit cases. */
static int t_gate_whole_jobs(void)
{
	/* array order is not chain order: 18 is downstream of 17 */
	struct sched_dstate d[3] = { D(18, 2, 0, 10, false), D(16, 9, 0, 10, true),
				     D(17, 3, 7, 10, false) };
	struct sched_dstate g[3];

	for (uint32_t mj = 0; mj <= 1; mj++) { /* off: rule 2 as written */
		memcpy(g, d, sizeof(d));
		sched_gate(g, 3, mj);
		CHECK(memcmp(g, d, sizeof(d)) == 0, "min_job %u changed the snapshot", mj);
	}
	memcpy(g, d, sizeof(d));
	sched_gate(g, 3, 4);
	/* 17: its producer 16 runs and only 3 < 4 items wait: held back */
	CHECK(!eligible(&g[2]), "17 should wait for a whole job");
	/* 18: its producer 17 is not running: 2 items are enough */
	CHECK(eligible(&g[0]) && g[0].ul == 2, "18 should run");
	CHECK(g[1].running && g[1].ul == 9, "a running task is left alone");
	g[2] = d[2];
	g[2].ul = 4;
	sched_gate(g, 3, 4);
	CHECK(eligible(&g[2]) && g[2].ul == 4, "a whole job upstream: 17 may run");

	/* room: 17's consumer 18 runs and only 10 - 7 = 3 < 4 slots are free */
	struct sched_dstate e[3] = { D(16, 9, 0, 10, false), D(17, 8, 7, 10, false),
				     D(18, 5, 0, 10, true) };
	memcpy(g, e, sizeof(e));
	sched_gate(g, 3, 4);
	CHECK(!eligible(&g[1]), "17 should wait for room for a whole job");
	CHECK(eligible(&g[0]), "16 has room and no running producer");
	g[1] = e[1];
	g[1].dl = 6;
	sched_gate(g, 3, 4);
	CHECK(eligible(&g[1]), "room for a whole job: 17 may run");
	/* the decision then follows the four rules on what is left */
	memcpy(g, e, sizeof(e));
	sched_gate(g, 3, 4);
	struct sched_choice c = sched_decide(MOTION_POLICY_HYBRID, NULL, 0, g, 3);
	CHECK(c.kind == SCHED_CHOICE_DATA && c.index == 0, "got %d/%d", c.kind, c.index);
	return 0;
}

/* Whole jobs: properties over random snapshots, with the neighbours found
 * by sorting on O (a different way than sched_gate's); one snapshot in
 * three has lanes (tasks that share an O): a neighbouring stage runs when
 * one of its lanes does. */
static int t_gate_random(void)
{
	uint32_t s = 77;
	unsigned held = 0;

	for (int it = 0; it < 200000; it++) {
		struct sched_dstate d[8], g[8];
		size_t nd = 1 + rnd(&s, 8);
		uint32_t mj = rnd(&s, 8);
		bool any_running = false;

		random_dstates(d, nd, &s, 10, 12, 3);
		if (nd > 2 && rnd(&s, 3) == 0)
			for (size_t i = 1; i < nd; i++)
				if (rnd(&s, 3) == 0)
					d[i].order = d[rnd(&s, (uint32_t)i)].order;
		for (size_t i = 0; i < nd; i++)
			any_running |= d[i].running;
		/* chain order */
		size_t idx[8];
		for (size_t i = 0; i < nd; i++)
			idx[i] = i;
		for (size_t i = 1; i < nd; i++)
			for (size_t k = i; k > 0 && d[idx[k - 1]].order > d[idx[k]].order; k--) {
				size_t t = idx[k];
				idx[k] = idx[k - 1];
				idx[k - 1] = t;
			}
		memcpy(g, d, sizeof(d));
		sched_gate(g, nd, mj);
		bool any_before = false, any_after = false;
		for (size_t r = 0; r < nd; r++) {
			size_t i = idx[r];
			bool up_run = false, dn_run = false;
			size_t a = r, b = r;
			while (a > 0 && d[idx[a - 1]].order == d[i].order)
				a--; /* the first of this stage's lanes */
			while (b + 1 < nd && d[idx[b + 1]].order == d[i].order)
				b++; /* the last */
			for (size_t k = a; k-- > 0 && d[idx[k]].order == d[idx[a - 1]].order;)
				up_run |= d[idx[k]].running;
			for (size_t k = b + 1; k < nd && d[idx[k]].order == d[idx[b + 1]].order; k++)
				dn_run |= d[idx[k]].running;
			bool held_now = eligible(&d[i]) && mj > 1 &&
					((up_run && d[i].ul < mj) ||
					 (dn_run && d[i].dcap - d[i].dl < mj));
			any_before |= eligible(&d[i]);
			any_after |= eligible(&g[i]);
			held += held_now;
			CHECK(g[i].order == d[i].order && g[i].running == d[i].running &&
			      g[i].dcap == d[i].dcap, "identity changed");
			CHECK(eligible(&g[i]) == (eligible(&d[i]) && !held_now),
			      "task %zu (O %u, ul %u, dl %u/%u, min_job %u, neighbours running %d/%d): eligible %d -> %d",
			      i, d[i].order, d[i].ul, d[i].dl, d[i].dcap, mj, up_run, dn_run,
			      eligible(&d[i]), eligible(&g[i]));
			if (eligible(&g[i]))
				CHECK(g[i].ul == d[i].ul && g[i].dl == d[i].dl,
				      "levels of an eligible task changed");
		}
		if (!any_running)
			CHECK(memcmp(g, d, nd * sizeof(d[0])) == 0,
			      "nothing runs, yet the gate changed the snapshot");
		/* liveness: something eligible before -> eligible after, or a
		 * job is running whose end lets it go */
		CHECK(!any_before || any_after || any_running, "gate stalled the pool");
	}
	CHECK(held > 1000, "only %u tasks held: the test does not exercise the gate", held);
	return 0;
}

static const struct test_case cases[] = {
	{ "gate_whole_jobs", t_gate_whole_jobs },
	{ "gate_random", t_gate_random },
	{ "periodic_wins", t_periodic_wins },
	{ "rule1_running", t_rule1_running },
	{ "rule2_data_and_room", t_rule2_data_and_room },
	{ "rule3_largest_difference", t_rule3_largest_difference },
	{ "rule4_tie_upstream", t_rule4_tie_upstream },
	{ "fifo_policy", t_fifo_policy },
	{ "random_vs_reference", t_random_vs_reference },
	{ "hybrid_balance", t_hybrid_balance },
	{ "hybrid_growth_and_caps", t_hybrid_growth_and_caps },
};

int main(int argc, char **argv)
{
	return test_main(argc, argv, cases, sizeof(cases) / sizeof(cases[0]));
}
