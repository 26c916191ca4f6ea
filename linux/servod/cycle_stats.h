/* SPDX-License-Identifier: MIT */
/*
 * cycle_stats.h - servod's counters: one struct, written under sd->lock by
 * the cycle thread (and by the supervisor for its recoveries and
 * restores), read under that lock by `ampctl stats`; the counters the
 * telemetry's STATS carry are published by one call, cycle_stats_publish(),
 * as relaxed 64-bit atomics (lock-free on ARMv7-A with LDREXD/STREXD, as
 * on x86-64) for the drain thread, which never takes sd->lock.
 */
#ifndef SERVOD_CYCLE_STATS_H
#define SERVOD_CYCLE_STATS_H

#include <stdatomic.h>
#include <stdint.h>

#include "amp/amp.h"
#include "cycle_irq.h"

struct telem_counter;

/* Wake-up latency histogram: LAT_BUCKETS buckets split at these edges (us). */
#define LAT_BUCKETS 10
extern const uint32_t lat_bucket_edges_us[LAT_BUCKETS - 1];

struct cycle_stats {
	uint64_t wakes;		/* cycle interrupts taken */
	uint64_t cycles;	/* amp_linux_cycle calls (session open) */
	uint64_t exchanges;	/* cycles with the servo attached and a fresh feedback */
	uint64_t absent;	/* cycles with the servo not attached */
	uint64_t missed_irq;	/* cycle interrupts never seen (time gaps) */
	uint64_t uio_skips;	/* UIO event count jumped by more than 1 */
	uint64_t late;		/* commands published after T/2 (the servo reads them then) */
	uint64_t stalls;	/* AMP_E_STALLED episodes (and lasting peer errors) reported */
	uint64_t peer_errors;	/* cycles with AMP_E_PEER_ERROR (servo state FAULT or garbage) */
	uint64_t stall_cycle;	/* cycles at which the last stall was detected */
	uint64_t recoveries;	/* crashes reported to remoteproc (supervisor) */
	uint64_t restores;	/* parameter sets loaded at an attach (supervisor) */
	uint64_t recovery_retries;	/* restarts begun again after a failed one (supervisor) */
	uint64_t recovery_failures;	/* restarts that did not bring the servo back (supervisor) */
	uint64_t latches;	/* faults latched: one restart too many within the window */
	uint64_t restore_errors;
	uint32_t lat_min, lat_max;	/* wake-up latency, ns */
	uint64_t lat_sum, lat_n;
	uint64_t lat_hist[LAT_BUCKETS];
	uint32_t work_max;	/* ns: wake-up to commands published */
	uint64_t work_sum;
	/* window markers: Linux cycle vs the servo's cycle in the last feedback */
	uint32_t servo_cycle;
	uint32_t servo_cmd_seq;
	/* last stall: Linux cycles and us from the servo's last heartbeat change to detection */
	uint32_t stall_cycles;
	uint32_t stall_us;
	/* the last commanded positions and the last actual ones (fresh feedback) */
	int32_t cmd_pos[AMP_MAX_AXES], act_pos[AMP_MAX_AXES];
	/* the last status word of each axis (fresh feedback): its drive state and error code */
	uint32_t ax_status[AMP_MAX_AXES];

	/* trackers of the cycle thread (not counters) */
	uint32_t last_count;	/* UIO event count of the last wake-up */
	int have_count;
	uint64_t last_event_ns;	/* time of the last interval event */
	uint32_t last_hb;	/* the servo's heartbeat, when it last changed, at which cycle */
	uint64_t last_hb_ns, last_hb_cycle;
	uint32_t stall_attach;	/* attach_count whose stall was reported (UINT32_MAX: none) */
	uint32_t peer_err_run;	/* consecutive cycles with AMP_E_PEER_ERROR */
};

/* The published counters, in the order of their telemetry names. */
enum { CYCLE_STATS_PUBLISHED = 9 };
struct cycle_stats_pub {
	_Atomic uint64_t v[CYCLE_STATS_PUBLISHED];
	/* a seqcount: odd while a cycle pushes its telemetry record and the
	 * counters change (cycle_stats_begin .. cycle_stats_end), so that the
	 * telemetry's STATS takes them and its own totals as one snapshot */
	_Atomic uint64_t seq;
};

/* A wake-up: count, latency, missed interval events (period_ns apart). */
void cycle_stats_wake(struct cycle_stats *s, const struct cycle_wake *w, uint32_t period_ns);
/* The servo's heartbeat as read in a cycle at time t_ns. */
void cycle_stats_heartbeat(struct cycle_stats *s, uint32_t hb, uint64_t t_ns);
/* The work of a cycle (wake-up to commands published) and whether it was late. */
void cycle_stats_work(struct cycle_stats *s, uint32_t lat_ns, uint32_t work_ns, uint32_t period_ns);
/* A stall of the servo attached as attach_count, detected at t_ns: 1 if new. */
int cycle_stats_stall(struct cycle_stats *s, uint32_t attach_count, uint64_t t_ns);
/*
 * The result rc of a cycle: a servo whose state word says FAULT (or is no
 * state at all) for limit consecutive cycles is reported like a stall
 * (recovery): 1 once per attach, when it is; counts the peer-error cycles.
 */
int cycle_stats_peer_error(struct cycle_stats *s, int rc, uint32_t limit, uint32_t attach_count, uint64_t t_ns);
/* A new session: the next stall is reported whatever the attach count. */
void cycle_stats_new_session(struct cycle_stats *s);

/*
 * Publishing the counters for the telemetry's drain thread. A cycle brackets
 * everything it changes, its telemetry record included, with
 * cycle_stats_begin() and cycle_stats_end() (which publishes);
 * cycle_stats_publish() is both at once, for a change outside a cycle.
 */
void cycle_stats_begin(struct cycle_stats_pub *p);
void cycle_stats_end(const struct cycle_stats *s, struct cycle_stats_pub *p);
void cycle_stats_publish(const struct cycle_stats *s, struct cycle_stats_pub *p);
/* The published counters as the telemetry's STATS application counters,
 * and their seqcount (telem_cfg.app_seq). */
unsigned cycle_stats_counters(void *pub, struct telem_counter *out, unsigned max);
uint64_t cycle_stats_seq(void *pub);

#endif
