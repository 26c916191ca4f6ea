/* SPDX-License-Identifier: MIT */
#define _POSIX_C_SOURCE 200809L
#include "scheduler.h"

#include <errno.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "motion/ring.h" /* RING_CACHELINE */
#include "servoamp/mono_clock.h"

struct sched_choice sched_decide(enum motion_policy policy,
				 const struct sched_pstate *p, size_t np,
				 const struct sched_dstate *d, size_t nd)
{
	struct sched_choice c = { SCHED_CHOICE_IDLE, -1 };
	int best = -1;

	/* A ready periodic task always wins: highest priority (lowest P),
	 * then the lowest index. */
	for (size_t i = 0; i < np; i++) {
		if (!p[i].ready || p[i].running)
			continue;
		if (best < 0 || p[i].prio < p[best].prio)
			best = (int)i;
	}
	if (best >= 0) {
		c.kind = SCHED_CHOICE_PERIODIC;
		c.index = best;
		return c;
	}

	for (size_t i = 0; i < nd; i++) {
		if (d[i].running)                /* rule 1 */
			continue;
		if (d[i].ul == 0 || d[i].dl >= d[i].dcap) /* rule 2 */
			continue;
		if (best < 0) {
			best = (int)i;
			continue;
		}
		const struct sched_dstate *b = &d[best];
		if (policy == MOTION_POLICY_FIFO) {
			/* longest-waiting runnable task first */
			if (d[i].last < b->last ||
			    (d[i].last == b->last && d[i].order < b->order))
				best = (int)i;
			continue;
		}
		int64_t di = (int64_t)d[i].ul - (int64_t)d[i].dl;
		int64_t db = (int64_t)b->ul - (int64_t)b->dl;
		if (di > db || (di == db && d[i].order < b->order)) /* 3, 4 */
			best = (int)i;
	}
	if (best >= 0) {
		c.kind = SCHED_CHOICE_DATA;
		c.index = best;
	}
	return c;
}

/* The chain positions (O, 0..255) present in the snapshot, and those with
 * a task running: a bit each. */
struct order_bits {
	uint64_t have[4], run[4];
};

static bool obit(const uint64_t *b, unsigned o)
{
	return (b[o >> 6] >> (o & 63)) & 1u;
}

void sched_gate(struct sched_dstate *d, size_t nd, uint32_t min_job)
{
	struct order_bits ob = { { 0 }, { 0 } };
	bool any = false;

	if (min_job <= 1)
		return;
	for (size_t i = 0; i < nd; i++) {
		ob.have[d[i].order >> 6] |= 1ull << (d[i].order & 63);
		if (d[i].running) {
			ob.run[d[i].order >> 6] |= 1ull << (d[i].order & 63);
			any = true;
		}
	}
	if (!any) /* one worker, or an idle pool: nothing to wait for */
		return;
	for (size_t i = 0; i < nd; i++) {
		int up = d[i].order - 1, dn = d[i].order + 1;

		if (d[i].running)
			continue;
		/* the neighbouring stages: the next smaller and the next
		 * larger O present; a stage of lanes runs if one lane does */
		while (up >= 0 && !obit(ob.have, (unsigned)up))
			up--;
		while (dn <= 255 && !obit(ob.have, (unsigned)dn))
			dn++;
		if (up >= 0 && obit(ob.run, (unsigned)up) && d[i].ul < min_job)
			d[i].ul = 0;
		if (dn <= 255 && obit(ob.run, (unsigned)dn) && d[i].dl < d[i].dcap &&
		    d[i].dcap - d[i].dl < min_job)
			d[i].dl = d[i].dcap;
	}
}

/*
 * Layout for several cores: every decision reads the state of every task,
 * and the worker that decides has usually not written it itself.  So what a
 * decision reads and the other workers write is kept small: the running
 * flags in one cache line, the dispatch sequence (FIFO only) in another, the
 * descriptors read-only after sched_create().  The per-job statistics are
 * kept per worker, each worker's on lines of its own, and added up by
 * sched_get_stats().
 */
struct task {
	struct sched_task_desc d;  /* read-only after sched_create() */
	uint64_t next_release;     /* periodic */
	uint64_t overruns;         /* periodic */
};

/* One worker's statistics: written by that worker only (under s->lock). */
struct wstats {
	_Alignas(RING_CACHELINE) uint64_t runs[SCHED_MAX_TASKS];
	uint64_t items[SCHED_MAX_TASKS];
	uint64_t busy_ns[SCHED_MAX_TASKS];
	uint64_t idle, job_ns, sleep_ns, life_ns;
};

struct worker {
	struct sched *s;
	unsigned id;
	pthread_t th;
};

struct sched {
	enum motion_policy policy;
	size_t n;
	struct task t[SCHED_MAX_TASKS];
	size_t np, nd;
	int pidx[SCHED_MAX_TASKS]; /* periodic -> task index */
	int didx[SCHED_MAX_TASKS]; /* data -> task index */
	_Alignas(RING_CACHELINE) bool running[SCHED_MAX_TASKS];
	_Alignas(RING_CACHELINE) uint64_t last[SCHED_MAX_TASKS]; /* data: dispatch sequence */
	uint64_t seq;
	_Alignas(RING_CACHELINE) pthread_mutex_t lock;
	pthread_cond_t cond;
	atomic_int waiting;
	atomic_bool stop;
	unsigned workers;
	atomic_bool started;
	struct worker w[SCHED_MAX_WORKERS];
	struct wstats ws[SCHED_MAX_WORKERS];
	uint64_t t0;
	uint32_t min_job;
	/* trace */
	unsigned nlevels;
	const char *level_name[SCHED_MAX_LEVELS];
	sched_sample_fn sample;
	void *sample_arg;
	pthread_mutex_t trace_lock;
	uint32_t trace_cap, trace_n;
	uint64_t trace_dropped;
	uint64_t *trace_t;
	uint32_t *trace_v;
};

struct sched *sched_create(enum motion_policy policy,
			   const struct sched_task_desc *tasks, size_t n,
			   uint32_t trace_samples)
{
	struct sched *s;
	pthread_condattr_t ca;

	if (n == 0 || n > SCHED_MAX_TASKS)
		return NULL;
	/* struct sched has cache-line aligned members: calloc() does not
	 * promise that alignment (its size is a multiple of it, as every
	 * type's is) */
	s = aligned_alloc(_Alignof(struct sched), sizeof(*s));
	if (!s)
		return NULL;
	memset(s, 0, sizeof(*s));
	s->policy = policy;
	s->n = n;
	s->t0 = mono_now_us();
	for (size_t i = 0; i < n; i++) {
		s->t[i].d = tasks[i];
		if (tasks[i].periodic) {
			if (tasks[i].period_us == 0)
				goto fail;
			s->pidx[s->np++] = (int)i;
			s->t[i].next_release = s->t0 + tasks[i].period_us;
		} else {
			if (!tasks[i].levels)
				goto fail;
			s->didx[s->nd++] = (int)i;
		}
		if (!tasks[i].run)
			goto fail;
	}
	if (trace_samples) {
		s->trace_t = calloc(trace_samples, sizeof(*s->trace_t));
		s->trace_v = calloc((size_t)trace_samples * SCHED_MAX_LEVELS,
				    sizeof(*s->trace_v));
		if (!s->trace_t || !s->trace_v)
			goto fail;
		s->trace_cap = trace_samples;
	}
	pthread_mutex_init(&s->lock, NULL);
	pthread_mutex_init(&s->trace_lock, NULL);
	pthread_condattr_init(&ca);
	pthread_condattr_setclock(&ca, CLOCK_MONOTONIC);
	pthread_cond_init(&s->cond, &ca);
	pthread_condattr_destroy(&ca);
	atomic_init(&s->waiting, 0);
	atomic_init(&s->stop, false);
	atomic_init(&s->started, false);
	return s;
fail:
	free(s->trace_t);
	free(s->trace_v);
	free(s);
	return NULL;
}

void sched_destroy(struct sched *s)
{
	if (!s)
		return;
	sched_stop(s);
	pthread_cond_destroy(&s->cond);
	pthread_mutex_destroy(&s->lock);
	pthread_mutex_destroy(&s->trace_lock);
	free(s->trace_t);
	free(s->trace_v);
	free(s);
}

void sched_set_min_job(struct sched *s, uint32_t min_job)
{
	pthread_mutex_lock(&s->lock);
	s->min_job = min_job;
	pthread_mutex_unlock(&s->lock);
}

void sched_set_sampler(struct sched *s, unsigned n, const char *const *names,
		       sched_sample_fn fn, void *arg)
{
	if (n > SCHED_MAX_LEVELS)
		n = SCHED_MAX_LEVELS;
	s->nlevels = n;
	for (unsigned i = 0; i < n; i++)
		s->level_name[i] = names[i];
	s->sample = fn;
	s->sample_arg = arg;
}

void sched_sample(struct sched *s)
{
	uint32_t v[SCHED_MAX_LEVELS] = { 0 };

	if (!s->sample || !s->trace_cap)
		return;
	s->sample(s->sample_arg, v);
	pthread_mutex_lock(&s->trace_lock);
	if (s->trace_n < s->trace_cap) {
		s->trace_t[s->trace_n] = mono_now_us() - s->t0;
		memcpy(&s->trace_v[(size_t)s->trace_n * SCHED_MAX_LEVELS], v,
		       sizeof(v));
		s->trace_n++;
	} else {
		s->trace_dropped++;
	}
	pthread_mutex_unlock(&s->trace_lock);
}

int sched_trace_csv(const struct sched *s, FILE *f)
{
	if (fprintf(f, "t_us") < 0)
		return -1;
	for (unsigned i = 0; i < s->nlevels; i++)
		fprintf(f, ",%s", s->level_name[i]);
	fputc('\n', f);
	for (uint32_t k = 0; k < s->trace_n; k++) {
		fprintf(f, "%llu", (unsigned long long)s->trace_t[k]);
		for (unsigned i = 0; i < s->nlevels; i++)
			fprintf(f, ",%u",
				s->trace_v[(size_t)k * SCHED_MAX_LEVELS + i]);
		fputc('\n', f);
	}
	return ferror(f) ? -1 : 0;
}

/* Under s->lock: snapshot the task states and decide. */
static struct sched_choice decide_locked(struct sched *s, uint64_t now)
{
	struct sched_pstate ps[SCHED_MAX_TASKS];
	struct sched_dstate ds[SCHED_MAX_TASKS];

	for (size_t i = 0; i < s->np; i++) {
		int ti = s->pidx[i];
		ps[i].prio = s->t[ti].d.prio;
		ps[i].ready = now >= s->t[ti].next_release;
		ps[i].running = s->running[ti];
	}
	for (size_t i = 0; i < s->nd; i++) {
		int ti = s->didx[i];
		const struct sched_task_desc *d = &s->t[ti].d;
		ds[i].order = d->order;
		ds[i].running = s->running[ti];
		ds[i].last = s->policy == MOTION_POLICY_FIFO ? s->last[ti] : 0;
		ds[i].ul = ds[i].dl = ds[i].dcap = 0;
		if (!ds[i].running)
			d->levels(d->arg, &ds[i].ul, &ds[i].dl, &ds[i].dcap);
	}
	sched_gate(ds, s->nd, s->min_job);
	return sched_decide(s->policy, ps, s->np, ds, s->nd);
}

/* Under s->lock: mark the chosen task running; returns its index. */
static int claim_locked(struct sched *s, struct sched_choice c, uint64_t now)
{
	int ti;

	if (c.kind == SCHED_CHOICE_PERIODIC) {
		ti = s->pidx[c.index];
		struct task *t = &s->t[ti];
		t->next_release += t->d.period_us;
		if (t->next_release <= now) { /* missed releases */
			t->overruns++;
			t->next_release = now + t->d.period_us;
		}
	} else {
		ti = s->didx[c.index];
		s->last[ti] = ++s->seq;
	}
	s->running[ti] = true;
	return ti;
}

/* Under s->lock: the bookkeeping of a finished job of task ti. */
static void job_done_locked(struct sched *s, struct wstats *ws, int ti,
			    uint32_t items, uint64_t ns)
{
	s->running[ti] = false;
	ws->runs[ti]++;
	ws->items[ti] += items;
	ws->busy_ns[ti] += ns;
}

static uint64_t next_release_locked(const struct sched *s)
{
	uint64_t nr = UINT64_MAX;

	for (size_t i = 0; i < s->np; i++) {
		int ti = s->pidx[i];
		if (!s->running[ti] && s->t[ti].next_release < nr)
			nr = s->t[ti].next_release;
	}
	return nr;
}

struct sched_choice sched_step(struct sched *s)
{
	struct sched_choice c;
	uint64_t now = mono_now_us();
	int ti;

	pthread_mutex_lock(&s->lock);
	c = decide_locked(s, now);
	if (c.kind == SCHED_CHOICE_IDLE) {
		s->ws[0].idle++;
		pthread_mutex_unlock(&s->lock);
		return c;
	}
	ti = claim_locked(s, c, now);
	pthread_mutex_unlock(&s->lock);

	uint64_t b0 = mono_now_ns();
	uint32_t items = s->t[ti].d.run(s->t[ti].d.arg, 0);
	uint64_t b1 = mono_now_ns();

	pthread_mutex_lock(&s->lock);
	job_done_locked(s, &s->ws[0], ti, items, b1 - b0);
	pthread_mutex_unlock(&s->lock);
	return c;
}

static void *worker_main(void *arg)
{
	struct worker *w = arg;
	struct sched *s = w->s;
	struct wstats *ws = &s->ws[w->id];
	int prev = -1;
	uint32_t prev_items = 0;
	uint64_t prev_ns = 0;
	uint64_t born = mono_now_ns();

	pthread_mutex_lock(&s->lock);
	for (;;) {
		if (prev >= 0) {
			job_done_locked(s, ws, prev, prev_items, prev_ns);
			ws->job_ns += prev_ns;
			prev = -1;
			if (atomic_load(&s->waiting) > 0)
				pthread_cond_broadcast(&s->cond);
		}
		if (atomic_load(&s->stop))
			break;
		/* Announce that we may sleep before reading the queue levels,
		 * so that a producer either sees us waiting or we see its data
		 * (sched_kick pairs with this). */
		atomic_fetch_add(&s->waiting, 1);
		atomic_thread_fence(memory_order_seq_cst);
		uint64_t now = mono_now_us();
		struct sched_choice c = decide_locked(s, now);
		if (c.kind == SCHED_CHOICE_IDLE) {
			uint64_t wake = next_release_locked(s);
			if (wake > now + 2000u)
				wake = now + 2000u; /* safety poll */
			struct timespec ts;
			mono_deadline(&ts, (wake > now ? wake - now : 0) * 1000u);
			ws->idle++;
			uint64_t z0 = mono_now_ns();
			int rc = pthread_cond_timedwait(&s->cond, &s->lock, &ts);
			(void)rc;
			ws->sleep_ns += mono_now_ns() - z0;
			atomic_fetch_sub(&s->waiting, 1);
			continue;
		}
		atomic_fetch_sub(&s->waiting, 1);
		prev = claim_locked(s, c, now);
		pthread_mutex_unlock(&s->lock);
		uint64_t b0 = mono_now_ns();
		prev_items = s->t[prev].d.run(s->t[prev].d.arg, w->id);
		prev_ns = mono_now_ns() - b0;
		pthread_mutex_lock(&s->lock);
	}
	ws->life_ns += mono_now_ns() - born;
	pthread_mutex_unlock(&s->lock);
	return NULL;
}

int sched_start(struct sched *s, unsigned workers)
{
	if (atomic_load(&s->started) || workers == 0 || workers > SCHED_MAX_WORKERS)
		return -1;
	atomic_store(&s->stop, false);
	s->workers = workers;
	atomic_store(&s->started, true);
	uint64_t now = mono_now_us();
	for (size_t i = 0; i < s->np; i++) {
		struct task *t = &s->t[s->pidx[i]];
		t->next_release = now + t->d.period_us;
	}
	for (unsigned i = 0; i < workers; i++) {
		s->w[i].s = s;
		s->w[i].id = i;
		if (pthread_create(&s->w[i].th, NULL, worker_main, &s->w[i])) {
			atomic_store(&s->stop, true);
			pthread_mutex_lock(&s->lock);
			pthread_cond_broadcast(&s->cond);
			pthread_mutex_unlock(&s->lock);
			for (unsigned k = 0; k < i; k++)
				pthread_join(s->w[k].th, NULL);
			atomic_store(&s->started, false);
			s->workers = 0;
			return -1;
		}
	}
	return 0;
}

void sched_stop(struct sched *s)
{
	if (!atomic_load(&s->started))
		return;
	atomic_store(&s->stop, true);
	pthread_mutex_lock(&s->lock);
	pthread_cond_broadcast(&s->cond);
	pthread_mutex_unlock(&s->lock);
	for (unsigned i = 0; i < s->workers; i++)
		pthread_join(s->w[i].th, NULL);
	atomic_store(&s->started, false);
}

void sched_kick(struct sched *s)
{
	atomic_thread_fence(memory_order_seq_cst);
	if (atomic_load(&s->started) && atomic_load(&s->waiting) > 0) {
		pthread_mutex_lock(&s->lock);
		pthread_cond_broadcast(&s->cond);
		pthread_mutex_unlock(&s->lock);
	}
}

void sched_get_stats(struct sched *s, struct sched_stats *st)
{
	memset(st, 0, sizeof(*st));
	pthread_mutex_lock(&s->lock);
	st->n_tasks = s->n;
	st->workers = s->workers ? s->workers : 1;
	for (size_t i = 0; i < s->n; i++) {
		st->name[i] = s->t[i].d.name;
		st->overruns[i] = s->t[i].overruns;
		for (unsigned w = 0; w < SCHED_MAX_WORKERS; w++) {
			st->runs[i][w] = s->ws[w].runs[i];
			st->items[i] += s->ws[w].items[i];
			st->busy_ns[i] += s->ws[w].busy_ns[i];
		}
	}
	for (unsigned w = 0; w < SCHED_MAX_WORKERS; w++) {
		const struct wstats *ws = &s->ws[w];
		uint64_t spent = ws->job_ns + ws->sleep_ns;

		st->idle[w] = ws->idle;
		st->job_ns[w] = ws->job_ns;
		st->sleep_ns[w] = ws->sleep_ns;
		st->sched_ns[w] = ws->life_ns > spent ? ws->life_ns - spent : 0;
	}
	st->decisions = s->seq;
	pthread_mutex_unlock(&s->lock);
}
