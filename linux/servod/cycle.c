// SPDX-License-Identifier: MIT
/*
 * cycle.c - the cycle thread (SCHED_FIFO, mlockall): waits for the cycle
 * interrupt (cycle_irq.h), then, under sd->lock, runs one exchange while
 * the session is open: the setpoint source's coarse setpoints (setpoint.h),
 * amp_linux_cycle() (heartbeat, semaphore, feedback read, commands written,
 * semaphore set), the telemetry record, and the counters (cycle_stats.h):
 * cycles, exchanges, missed interrupts, late cycles, wake-up latency, and a
 * stall of the servo, its feedback refused (AMP_E_FEEDBACK), or a servo in
 * FAULT (or with a garbled state word) for wd_limit cycles, which the
 * supervisor reports for recovery.
 */
#define _GNU_SOURCE
#include <string.h>

#include "context.h"

/* One exchange: setpoints, amp_linux_cycle(), record, counters. */
static void exchange(struct servod *sd, struct amp_cmd_axis *cmd, const struct cycle_wake *w)
{
	struct cycle_stats *st = &sd->stats;
	const struct setpoint_ops *src = setpoint_source(sd);
	/* cmd[] has AMP_MAX_AXES (axes is range-checked where it is set) */
	uint32_t n = sd->axes <= AMP_MAX_AXES ? sd->axes : AMP_MAX_AXES, nfb;
	struct amp_peer_info pi;
	struct amp_rx_info rx;
	uint64_t t_done;
	uint32_t judged;
	int rc, fresh;

	src->fill(sd, cmd, n, sd->amp.cmd_seq + 1u);
	/* 2-5: semaphore, feedback, commands, semaphore */
	memset(&rx, 0, sizeof(rx));
	rc = amp_linux_cycle(&sd->amp, cmd, n, SP_CMDF_MOTION, &rx);
	t_done = mono_now_ns();
	/*
	 * A stall (or a peer error) is the firmware's whose heartbeat this
	 * cycle judged: the attach_count amp_linux_cycle read, not pi's, read
	 * later. A restarted firmware attaching in between would otherwise
	 * take the old one's stall for its own (a failed restart) and, its
	 * attach_count then marked as reported, never have its own stall
	 * reported.
	 */
	judged = sd->amp.servo_attach;
	fresh = (rc == AMP_OK || rc == AMP_E_PEER_ERROR) &&
		(rx.status == AMP_RX_FRESH || rx.status == AMP_RX_MISSED);
	if (src->feedback)
		src->feedback(sd, rc, &sd->amp.fb, n, fresh);
	st->cycles++;
	for (uint32_t i = 0; i < n && i < AMP_MAX_AXES; i++)
		st->cmd_pos[i] = cmd[i].target_pos;
	/* the axes the feedback covers (amp_lib bounds its count) */
	nfb = sd->amp.fb.n_axes < n ? sd->amp.fb.n_axes : n;
	if (rc == AMP_OK && fresh)
		for (uint32_t i = 0; i < nfb; i++) {
			st->act_pos[i] = sd->amp.fb.axis[i].actual_pos;
			st->ax_status[i] = sd->amp.fb.axis[i].status_word;
		}
	telemetry_cycle(sd, w, rc, &rx, cmd, n);
	(void)amp_linux_peer_info((const void *)sd->ocm, sd->ocm_size, &pi);
	cycle_stats_heartbeat(st, pi.heartbeat, w->t_ns);
	cycle_stats_work(st, w->lat_ns, (uint32_t)(t_done - w->t_ns), sd->period_ns);
	if (rc == AMP_E_PEER_ABSENT) {
		st->absent++;
	} else if (rc == AMP_E_STALLED || rc == AMP_E_FEEDBACK) {
		/* no heartbeat, or no feedback taken (every record refused)
		 * for wd_limit cycles: both recovered as a stall */
		if (cycle_stats_stall(st, judged, w->t_ns))
			atomic_store(&sd->session.stall_pending, STALL_HEARTBEAT);
	}
	/* a servo whose state word says FAULT (or garbage) for wd_limit
	 * cycles: recovered like a stall */
	if (cycle_stats_peer_error(st, rc, sd->amp.wd.limit, judged, w->t_ns))
		atomic_store(&sd->session.stall_pending, STALL_PEER_ERROR);
	else if (rc == AMP_OK || rc == AMP_E_PEER_ERROR) {
		if (rx.status == AMP_RX_FRESH || rx.status == AMP_RX_MISSED)
			st->exchanges++;
		st->servo_cycle = sd->amp.fb.cycle;
		st->servo_cmd_seq = sd->amp.fb.cmd_seq;
	}
}

void *cycle_thread(void *arg)
{
	struct servod *sd = arg;
	struct amp_cmd_axis cmd[AMP_MAX_AXES];

	memset(cmd, 0, sizeof(cmd));
	while (!servod_quitting(sd)) {
		struct cycle_wake w;

		if (cycle_irq_wait(sd, &sd->irq, &w))
			continue;
		pthread_mutex_lock(&sd->lock);
		cycle_stats_begin(&sd->pub);	/* the record and the counters: one change */
		cycle_stats_wake(&sd->stats, &w, sd->period_ns);
		if (session_open(&sd->session))
			exchange(sd, cmd, &w);
		cycle_stats_end(&sd->stats, &sd->pub);
		pthread_mutex_unlock(&sd->lock);
	}
	return 0;
}
