/* SPDX-License-Identifier: MIT */
/*
 * amp.h - amp_lib public API: the OCM transport between Linux (the
 * application core) and the servo core. Freestanding C11, no dynamic
 * allocation; every object is owned by the caller.
 *
 * Linux side (amp_linux_*)              servo side (amp_servo_*)
 *   amp_linux_init()  servo offline       amp_servo_attach()
 *   amp_linux_cycle() every interrupt     amp_servo_cycle_rx() / _tx()
 *   amp_linux_mbox_call()                 amp_servo_mbox_poll() / _respond()
 *
 * The layout is in amp_ocm_layout.h, the protocol in docs/amp-protocol.md.
 */
#ifndef AMP_AMP_H
#define AMP_AMP_H

#include <stdint.h>

#include "amp/amp_ocm_layout.h"
#include "amp/amp_port.h"

/* Error codes: 0 or negative. */
enum {
	AMP_OK = 0,
	AMP_E_PEER_ABSENT = -1,	/* peer not attached to the current epoch */
	AMP_E_PEER_ERROR = -2,	/* peer reported a fault */
	AMP_E_TIMEOUT = -3,	/* peer did not answer in time */
	AMP_E_PROTO = -4,	/* protocol violation: magic, CRC, seq, length */
	AMP_E_INVAL = -5,	/* bad argument from the local caller */
	AMP_E_LAYOUT = -6,	/* region magic/version/size/config mismatch */
	AMP_E_BUSY = -7,	/* peer still owns the previous transaction */
	AMP_E_NOSPC = -8,	/* payload larger than the mailbox capacity */
	AMP_E_STALLED = -9,	/* peer heartbeat still for wd_limit cycles */
	AMP_E_FEEDBACK = -10,	/* no feedback taken for wd_limit cycles: reads refused */
	AMP_E_PEER_STOPPING = -11,	/* peer stopping on request: its heartbeat ends */
};

/* Returns a static string naming an AMP_E_* code. */
const char *amp_strerror(int err);

/* What a periodic read found. */
enum amp_rx_status {
	AMP_RX_FRESH = 0,	/* the next record, whole */
	AMP_RX_STALE = 1,	/* nothing new since the last read */
	AMP_RX_TORN = 2,	/* caught mid-write; previous data kept */
	AMP_RX_MISSED = 3,	/* a newer record, whole, but some skipped */
	AMP_RX_INVALID = 4,	/* fails validation (epoch, count, order) */
};

struct amp_rx_info {
	uint32_t status;	/* enum amp_rx_status */
	uint32_t seq;		/* sequence of the record now held */
	uint32_t missed;	/* records skipped (AMP_RX_MISSED) */
};

/* Counters kept by each side (local memory, never shared). */
struct amp_stats {
	uint32_t cycles;
	uint32_t fresh;
	uint32_t stale;
	uint32_t torn;
	uint32_t missed;	/* sum of skipped records */
	uint32_t invalid;
	uint32_t peer_late;	/* Linux: semaphore still busy at cycle start */
	uint32_t mbox_ok;
	uint32_t mbox_err;
	uint32_t sem_corrupt;	/* Linux: a semaphore word neither IDLE nor BUSY, repaired */
};

/* Heartbeat watchdog over the peer's counter, fed once per cycle. */
struct amp_watchdog {
	uint32_t last;
	uint32_t still;		/* cycles without change */
	uint32_t limit;
	uint32_t primed;
};

/* Returns AMP_OK, or AMP_E_STALLED once hb has not moved for limit cycles. */
int amp_wd_feed(struct amp_watchdog *wd, uint32_t hb);

/* CRC-32 (IEEE 802.3, reflected, as zlib) continued from crc. */
uint32_t amp_crc32(uint32_t crc, const void *data, uint32_t len);

/* ------------------------------------------------------------------ */
/* Linux (application core) side                                       */

struct amp_linux {
	struct amp_ocm *ocm;
	uint32_t epoch;
	uint32_t cycle;
	uint32_t cmd_seq;	/* last published command sequence */
	uint32_t fb_seq;	/* last feedback sequence read */
	uint32_t mbox_seq;
	uint32_t mbox_pending;	/* a request is out, answer not read */
	uint32_t servo_attach;	/* servo attach_count last seen: the attach the last cycle judged */
	uint32_t peer_seen;	/* the servo attached in this epoch: watchdog armed */
	uint32_t fb_resync;	/* a new attach seen: take its first whole record */
	uint32_t fb_bad;	/* cycles without a record taken since a refused read */
	uint32_t lstate;	/* Linux's state word as last set (READY, STOPPED) */
	struct amp_ocm_header hdr;	/* the header as written at init */
	struct amp_watchdog wd;
	struct amp_stats st;
	struct amp_fb_record fb;	/* last whole feedback */
};

/*
 * Initialise the region for a new session: the servo core must be offline
 * (not started, stopped, or crashed). Writes a new non-zero epoch so that
 * nothing left in OCM is taken for a live peer. wd_limit 0 = default.
 */
int amp_linux_init(struct amp_linux *l, void *base, uint32_t size, uint32_t wd_limit);

/* Mark the link closed (servo sees the Linux state change; a later
 * amp_linux_cycle() writes STOPPED again, not READY). */
void amp_linux_close(struct amp_linux *l);

/*
 * AMP_OK if the servo is attached to this epoch and running (or in safe
 * stop), AMP_E_PEER_STOPPING if its state word says it is stopping on a
 * request (remoteproc's stop: not a fault, its heartbeat ends),
 * AMP_E_PEER_ABSENT if not attached (another epoch, and no attach
 * in this one yet: attach_count 0 and none seen), AMP_E_PEER_ERROR if
 * attached but its state word says FAULT, OFFLINE (an attach writes
 * RUNNING before the epoch, and nothing writes OFFLINE after it) or is no
 * AMP_SSTATE_* at all, or its epoch word changed after it attached in this
 * epoch: words a stray write left, which the caller recovers (servod
 * restarts the firmware), never an absence it would wait on forever.
 */
int amp_linux_peer(const struct amp_linux *l);

/* The servo's own line in the region, as the Linux side reads it. */
struct amp_peer_info {
	uint32_t state;		/* AMP_SSTATE_* */
	uint32_t fault;		/* the servo's fault word (AMP_E_* or application code) */
	uint32_t epoch;		/* epoch the servo attached to */
	uint32_t attach_count;	/* attaches in that epoch (restarts, recoveries) */
	uint32_t heartbeat;	/* +1 every servo cycle */
};

/*
 * Read the servo's line from the region at base (size bytes), whether or
 * not amp_linux_init() ran on it: the words as they are, for status and
 * supervision. AMP_OK, or AMP_E_INVAL (NULL, misaligned, region too small).
 */
int amp_linux_peer_info(const void *base, uint32_t size, struct amp_peer_info *pi);

/* Change the heartbeat watchdog limit (cycles, 0 = default) of a link. */
int amp_linux_set_wd_limit(struct amp_linux *l, uint32_t wd_limit);

/*
 * One periodic cycle, the periodic exchange's Linux steps: heartbeat, check the
 * semaphore and the newest feedback's sequence, write the commands (n_axes <=
 * AMP_MAX_AXES), set the semaphore, publish, then read the feedback record
 * that sequence named (into l->fb, described by rx). Returns AMP_OK,
 * AMP_E_INVAL, AMP_E_PEER_ABSENT (servo not attached, commands still
 * published), AMP_E_PEER_ERROR (state FAULT or garbage), AMP_E_STALLED,
 * AMP_E_FEEDBACK or AMP_E_PEER_STOPPING. The heartbeat watchdog runs from
 * the servo's first attach in this epoch on, whatever the servo's state
 * word says afterwards, except STOPPING: a servo that says it stops on
 * request is never a stall (AMP_E_PEER_STOPPING, its watchdog re-armed).
 * Otherwise AMP_E_STALLED (heartbeat still for wd_limit cycles) takes
 * precedence over the rest. A new attach (the servo's attach_count changed) resynchronises
 * the feedback: its first whole record of this epoch is taken (FRESH)
 * whatever its sequence, unless it is word for word the record l->fb
 * already holds (STALE: nothing new). AMP_E_FEEDBACK, next in precedence:
 * a read was refused (INVALID or TORN) and no record has been taken for
 * wd_limit cycles since, however the servo beats: the link is as good as
 * stalled. Every cycle also writes Linux's own words again, unchanged (the
 * header as written at init, Linux's state word): a stray write to them
 * lasts one cycle instead of keeping the servo from attaching.
 */
int amp_linux_cycle(struct amp_linux *l, const struct amp_cmd_axis *axes,
		    uint32_t n_axes, uint32_t flags, struct amp_rx_info *rx);

/* A mailbox message: payload buffer owned by the caller. */
struct amp_msg {
	uint32_t command;
	int32_t status;		/* response: the servo's status */
	uint32_t length;	/* bytes in data */
	uint32_t capacity;	/* bytes available at data (response) */
	void *data;
};

/*
 * Non-periodic request/response (the mailbox's 7 Linux steps), polling with
 * a timeout in port ticks. On AMP_OK, resp holds the validated answer
 * (resp->status is the servo's status): the payload is copied out of OCM
 * once and the CRC is checked on that copy, so what the caller gets is what
 * was checked, whatever the servo writes meanwhile. On AMP_E_PROTO resp->data
 * may hold a rejected copy. AMP_E_BUSY: the servo still owns
 * an earlier request (it timed out) and has not answered it yet.
 */
int amp_linux_mbox_call(struct amp_linux *l, const struct amp_msg *req,
			struct amp_msg *resp, amp_ticks_t timeout);

/* The two halves of amp_linux_mbox_call, for callers that poll. */
int amp_linux_mbox_post(struct amp_linux *l, const struct amp_msg *req);
/* AMP_OK when answered, AMP_E_BUSY while pending, other errors final. */
int amp_linux_mbox_poll(struct amp_linux *l, struct amp_msg *resp);
/*
 * Give up on the request in flight (the caller's own timeout): counted as
 * a mailbox error; the servo still owns the token until it answers, so the
 * next post returns AMP_E_BUSY until then. AMP_OK, or AMP_E_INVAL if no
 * request is pending.
 */
int amp_linux_mbox_cancel(struct amp_linux *l);

/* ------------------------------------------------------------------ */
/* Servo side                                                          */

struct amp_servo {
	struct amp_ocm *ocm;
	uint32_t epoch;
	uint32_t cycle;
	uint32_t heartbeat;
	uint32_t fb_seq;
	uint32_t cmd_seq;	/* last command sequence consumed (cmd_pub at the attach) */
	uint32_t cmd_resync;	/* attached, no commands taken since: take the first whole ones */
	uint32_t mbox_state;	/* 0 idle, 1 request handed out */
	uint32_t mbox_seq;
	uint32_t mbox_cmd;
	uint32_t state;		/* the servo line's state word as this servo last wrote it */
	struct amp_watchdog wd;
	struct amp_stats st;
	struct amp_cmd_record cmd;	/* last whole commands */
	/* the request handed out: a private copy, validated (never OCM) */
	uint32_t req_buf[AMP_MBOX_CAPACITY / 4u];
};

/*
 * Attach to the region Linux initialised: AMP_OK, AMP_E_PEER_ABSENT (no
 * valid region yet: retry later) or AMP_E_LAYOUT (built differently).
 * The feedback records of an earlier attach are invalidated (epoch word
 * 0), the feedback sequence continues after the newest one found in
 * fb_pub and in both records (never a sequence an earlier attach wrote),
 * and the first whole commands of this epoch are taken whatever their
 * sequence: nothing either side reads after an attach depends on what the
 * sequence words held before it.
 */
int amp_servo_attach(struct amp_servo *s, void *base, uint32_t size);

/* +1 on the servo heartbeat (also done by amp_servo_cycle_rx). */
void amp_servo_heartbeat(struct amp_servo *s);

/* Publish the servo state (AMP_SSTATE_*) and a fault code. */
void amp_servo_set_state(struct amp_servo *s, uint32_t state, uint32_t fault);

/*
 * Cycle steps 1-3: heartbeat, wait up to timeout ticks for the semaphore
 * (0 = do not wait), read the commands into s->cmd (kept from the last
 * good record unless rx says FRESH or MISSED). Returns AMP_OK,
 * AMP_E_STALLED (Linux heartbeat still for wd_limit cycles),
 * AMP_E_PEER_ABSENT (Linux closed or re-initialised the region).
 */
int amp_servo_cycle_rx(struct amp_servo *s, amp_ticks_t timeout, struct amp_rx_info *rx);

/* Cycle steps 4-5: write the feedback, release the semaphore. The record's
 * cmd_seq is the last command sequence this servo took since its attach, 0
 * before the first: never one it did not take. */
int amp_servo_cycle_tx(struct amp_servo *s, const struct amp_fb_axis *axes,
		       uint32_t n_axes, uint32_t t_cycle, uint32_t irq_latency);

/*
 * A request handed to the servo application. payload points to the copy
 * in struct amp_servo that passed the checks (valid until the answer):
 * the peer cannot change it after validation.
 */
struct amp_mbox_req {
	uint32_t command;
	uint32_t length;
	const uint8_t *payload;
};

/*
 * Non-blocking: 1 and *req if a validated request waits for an answer,
 * 0 if none, AMP_E_PROTO if an invalid request arrived (already answered
 * with status AMP_E_PROTO).
 */
int amp_servo_mbox_poll(struct amp_servo *s, struct amp_mbox_req *req);

/* Answer the request handed out by amp_servo_mbox_poll. */
int amp_servo_mbox_respond(struct amp_servo *s, int32_t status,
			   const void *payload, uint32_t len);

#endif /* AMP_AMP_H */
