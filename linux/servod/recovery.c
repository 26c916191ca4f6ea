// SPDX-License-Identifier: MIT
/* recovery.c - the bounds on servod's recovery: the restart count in a
 * window and the backoff (recovery.h). */
#define _GNU_SOURCE
#include <string.h>

#include "recovery.h"

uint32_t recovery_in_window(const struct recovery *r, const struct recovery_cfg *c, uint64_t at_ns)
{
	uint64_t w = (uint64_t)c->window_ms * 1000000u;
	uint32_t n = 0;

	for (uint32_t i = 0; i < r->nhist && i < RECOVERY_HISTORY_MAX; i++)
		if (r->hist[i] <= at_ns && at_ns - r->hist[i] < w)
			n++;
	return n;
}

int recovery_may_restart(const struct recovery *r, const struct recovery_cfg *c, uint64_t at_ns)
{
	return !c->limit || recovery_in_window(r, c, at_ns) < c->limit;
}

void recovery_note_restart(struct recovery *r, uint64_t now_ns)
{
	r->hist[r->hist_next % RECOVERY_HISTORY_MAX] = now_ns;
	r->hist_next = (r->hist_next + 1u) % RECOVERY_HISTORY_MAX;
	if (r->nhist < RECOVERY_HISTORY_MAX)
		r->nhist++;
}

uint64_t recovery_backoff_ns(const struct recovery_cfg *c, uint32_t n)
{
	uint64_t ms = c->backoff_ms, max = c->backoff_max_ms > c->backoff_ms ? c->backoff_max_ms : c->backoff_ms;

	for (uint32_t i = 1; i < n && ms < max; i++)
		ms *= 2u;
	return (ms < max ? ms : max) * 1000000u;
}

void recovery_clear(struct recovery *r)
{
	int off = r->kernel_recovery_off;

	memset(r, 0, sizeof(*r));
	r->kernel_recovery_off = off;
}

const char *recovery_phase_name(enum restart_phase p)
{
	switch (p) {
	case RESTART_NONE: return "none";
	case RESTART_STOP: return "stop";
	case RESTART_START: return "start";
	case RESTART_ATTACH: return "attach";
	case RESTART_BACKOFF: return "backoff";
	}
	return "?";
}
