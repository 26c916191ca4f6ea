// SPDX-License-Identifier: MIT
/*
 * amp_linux.c - the application-core (Linux) side of amp_lib: region
 * initialisation, the periodic cycle, and the mailbox requester.
 */
#include "amp_internal.h"

int amp_linux_init(struct amp_linux *l, void *base, uint32_t size, uint32_t wd_limit)
{
	struct amp_ocm *o = base;
	struct amp_ocm_header h = { 0 };
	uint32_t *w = base;

	if (!l || !o || ((uintptr_t)base % AMP_CACHE_LINE) != 0 || size < sizeof(*o))
		return AMP_E_INVAL;
	if (wd_limit == 0)
		wd_limit = AMP_WD_LIMIT_DEFAULT;
	if (wd_limit > AMP_WD_LIMIT_MAX)
		return AMP_E_INVAL;

	/* A new epoch, different from whatever the region held before. */
	AMP_PORT_CACHE_INVAL(o, sizeof(*o));
	h.epoch = RD(&o->hdr.epoch) + 1u;
	if (h.epoch == 0)
		h.epoch = 1;

	/* Invalidate first, so a half-written region never looks valid. */
	WR(&o->linux_line.state, AMP_LSTATE_INIT);
	WR(&o->hdr.magic, 0);
	MB();
	for (uint32_t i = 0; i < sizeof(*o) / 4u; i++)
		if (&w[i] != &o->hdr.magic && &w[i] != &o->linux_line.state)
			WR(&w[i], 0);
	WR(&o->cyc_sem.sem, AMP_SEM_IDLE);
	WR(&o->mbox_sem.sem, AMP_SEM_IDLE);

	h.magic = AMP_OCM_MAGIC;
	h.version = AMP_OCM_VERSION;
	h.total_size = (uint32_t)sizeof(*o);
	h.max_axes = AMP_MAX_AXES;
	h.mbox_capacity = AMP_MBOX_CAPACITY;
	h.wd_limit = wd_limit;
	h.crc32 = amp_crc32(0, &h, offsetof(struct amp_ocm_header, crc32));
	amp__copy_out(&o->hdr, &h, sizeof(h));
	AMP_PORT_CACHE_CLEAN(o, sizeof(*o));
	WR_REL(&o->linux_line.state, AMP_LSTATE_READY);
	AMP_PORT_CACHE_CLEAN(&o->linux_line, 4u);

	*l = (struct amp_linux){ 0 };
	l->ocm = o;
	l->epoch = h.epoch;
	l->wd.limit = wd_limit;
	l->hdr = h;
	l->lstate = AMP_LSTATE_READY;
	return AMP_OK;
}

void amp_linux_close(struct amp_linux *l)
{
	if (l && l->ocm) {
		l->lstate = AMP_LSTATE_STOPPED;
		WR_REL(&l->ocm->linux_line.state, AMP_LSTATE_STOPPED);
		AMP_PORT_CACHE_CLEAN(&l->ocm->linux_line, 4u);
	}
}

int amp_linux_peer(const struct amp_linux *l)
{
	const struct amp_servo_line *sl = &l->ocm->servo_line;
	uint32_t state, epoch;

	AMP_PORT_CACHE_INVAL(sl, sizeof(*sl));
	epoch = RD_ACQ(&sl->epoch);
	state = RD(&sl->state);
	/* Another epoch word: before any attach in this epoch (none seen,
	 * attach_count still the 0 Linux wrote), the servo of an earlier one
	 * (absent). After one, the servo only ever rewrites the same epoch,
	 * so another value is a stray write: a peer error, which the caller
	 * recovers, not an absence it would wait on forever (the stray write
	 * may even come between the attach and Linux's first look at it). */
	if (epoch != l->epoch)
		return l->peer_seen || RD(&sl->attach_count) != 0 ? AMP_E_PEER_ERROR
								  : AMP_E_PEER_ABSENT;
	if (state == AMP_SSTATE_RUNNING || state == AMP_SSTATE_SAFESTOP)
		return AMP_OK;
	if (state == AMP_SSTATE_STOPPING)
		return AMP_E_PEER_STOPPING;
	/* FAULT, OFFLINE (the attach that wrote this epoch wrote RUNNING
	 * before it, and nothing writes OFFLINE after: a stray write) or a
	 * word that is no state at all: the peer is attached to this epoch
	 * but not sane */
	return AMP_E_PEER_ERROR;
}

int amp_linux_peer_info(const void *base, uint32_t size, struct amp_peer_info *pi)
{
	const struct amp_ocm *o = base;
	const struct amp_servo_line *sl;

	if (!o || !pi || ((uintptr_t)base % AMP_CACHE_LINE) != 0 || size < sizeof(*o))
		return AMP_E_INVAL;
	sl = &o->servo_line;
	AMP_PORT_CACHE_INVAL(sl, sizeof(*sl));
	pi->epoch = RD_ACQ(&sl->epoch);
	pi->state = RD_ACQ(&sl->state);
	pi->fault = RD_ACQ(&sl->fault);
	pi->attach_count = RD_ACQ(&sl->attach_count);
	pi->heartbeat = RD_ACQ(&sl->heartbeat);
	return AMP_OK;
}

int amp_linux_set_wd_limit(struct amp_linux *l, uint32_t wd_limit)
{
	if (!l)
		return AMP_E_INVAL;
	if (wd_limit == 0)
		wd_limit = AMP_WD_LIMIT_DEFAULT;
	if (wd_limit > AMP_WD_LIMIT_MAX)
		return AMP_E_INVAL;
	l->wd.limit = wd_limit;
	return AMP_OK;
}

/*
 * The servo's attach: its first in this epoch (peer_seen), or a new one
 * (attach_count changed, read once). Either gives it a fresh watchdog
 * and resynchronises the feedback: the new attach's sequence owes
 * nothing to the one read so far (a stray write to fb_pub while the servo
 * was down would otherwise leave every record "reordered" for as many
 * cycles as the sequence went back). Before the feedback is read, so that
 * the cycle that sees the attach already takes its first record.
 */
static void check_attach(struct amp_linux *l, int peer)
{
	uint32_t attach;
	int first = 0;

	if (!l->peer_seen) {
		if (peer != AMP_OK && peer != AMP_E_PEER_ERROR)
			return;
		l->peer_seen = 1;
		first = 1;
	}
	attach = RD_ACQ(&l->ocm->servo_line.attach_count);	/* read once */
	if (attach != l->servo_attach || first) {
		l->servo_attach = attach;
		l->wd.primed = 0;	/* a restarted servo gets a fresh watchdog */
		l->fb_resync = 1;
		l->fb_bad = 0;
	}
}

/* the record fb_pub named (pub, read by an acquire load in step 2 of
 * amp_linux_cycle, before the commands were published) */
static void read_feedback(struct amp_linux *l, struct amp_rx_info *rx, uint32_t pub)
{
	struct amp_ocm *o = l->ocm;

	if (amp__rx_record(&l->fb, 1, o->fb, FB_WORDS, FB_END, FB_NAXES, FB_SLOT, pub,
			   l->fb_seq, l->epoch, &l->fb_resync, rx, &l->st)) {
		l->fb_seq = pub;
		l->fb_bad = 0;
	} else if (rx->status == AMP_RX_INVALID || rx->status == AMP_RX_TORN || l->fb_bad) {
		/* from a refused read on, every cycle without a record
		 * taken counts (bounded: the limit is at most
		 * AMP_WD_LIMIT_MAX) */
		if (l->fb_bad < AMP_WD_LIMIT_MAX)
			l->fb_bad++;
	}
}

int amp_linux_cycle(struct amp_linux *l, const struct amp_cmd_axis *axes,
		    uint32_t n_axes, uint32_t flags, struct amp_rx_info *rx)
{
	struct amp_rx_info tmp;
	uint32_t h[AMP_REC_HDR_WORDS];	/* words 1..7, each set below */
	struct amp_ocm *o;
	uint32_t seq, sem, fb_pub;
	int peer;

	if (!l || !l->ocm || n_axes > AMP_MAX_AXES || (n_axes && !axes))
		return AMP_E_INVAL;
	if (!rx)
		rx = &tmp;
	o = l->ocm;
	peer = amp_linux_peer(l);

	/* 1. heartbeat (the caller has cleared its interrupt flag): counted
	 * here, written with the publication in step 4 so that the line the
	 * servo polls changes once per cycle */
	l->cycle++;
	l->st.cycles++;
	check_attach(l, peer);

	/* 2. semaphore: still busy means the servo has not taken the last
	 * commands (it is late or absent) */
	AMP_PORT_CACHE_INVAL(&o->cyc_sem, 4u);
	if (RD_ACQ(&o->cyc_sem.sem) == AMP_SEM_BUSY && peer == AMP_OK)
		l->st.peer_late++;
	/* ... and the newest feedback's sequence: the record read in step 5
	 * is the one published before this cycle's commands, whenever the
	 * servo answers them */
	AMP_PORT_CACHE_INVAL(&o->servo_line, sizeof(o->servo_line));
	fb_pub = RD_ACQ(&o->servo_line.fb_pub);

	/* 3. switch the command buffer: write and publish */
	/* (the record's header, then the caller's n_axes slots straight to
	 * OCM: no record built in private memory first) */
	h[AMP_REC_W(struct amp_cmd_record, epoch)] = l->epoch;
	h[AMP_REC_W(struct amp_cmd_record, cycle)] = l->cycle;
	h[CMD_NAXES] = n_axes;
	h[AMP_REC_W(struct amp_cmd_record, flags)] = flags;
	h[AMP_REC_W(struct amp_cmd_record, reserved[0])] = 0;
	h[AMP_REC_W(struct amp_cmd_record, reserved[1])] = 0;
	h[AMP_REC_W(struct amp_cmd_record, reserved[2])] = 0;
	seq = l->cmd_seq + 1u;
	amp__rec_write(&o->cmd[seq & 1u], h, axes, n_axes * CMD_SLOT, CMD_END, seq);

	/* 4. set the semaphore if the token is ours (idle), THEN publish the
	 * sequence: a servo that sees the new sequence always finds the
	 * semaphore busy and hands it back, so "busy" never outlives the
	 * exchange it stands for */
	AMP_PORT_CACHE_INVAL(&o->cyc_sem, 4u);
	sem = RD_ACQ(&o->cyc_sem.sem);
	if (sem != AMP_SEM_BUSY) {
		/* a word that is neither IDLE nor BUSY is a stray write: the
		 * token is handed to the servo as if it were idle (the
		 * sequence, not the semaphore, says which commands are new) */
		if (sem != AMP_SEM_IDLE)
			l->st.sem_corrupt++;
		WR_REL(&o->cyc_sem.sem, AMP_SEM_BUSY);
		AMP_PORT_CACHE_CLEAN(&o->cyc_sem, 4u);
	}
	/* Linux's own words, written again unchanged: the header as written
	 * at init, then its state. A stray write to either would otherwise
	 * keep the servo from attaching (AMP_E_PEER_ABSENT for ever, if it
	 * came before the servo's first attach in this epoch); now it lasts
	 * one cycle. The servo reads the same values before and after. */
	amp__copy_out(&o->hdr, &l->hdr, sizeof(l->hdr));
	WR(&o->linux_line.state, l->lstate);
	WR(&o->linux_line.heartbeat, l->cycle);
	WR(&o->linux_line.cycle, l->cycle);
	WR_REL(&o->linux_line.cmd_pub, seq);
	AMP_PORT_CACHE_CLEAN(&o->linux_line, sizeof(o->linux_line));
	l->cmd_seq = seq;
	AMP_PORT_SIGNAL();

	/* 5. switch the response buffer: read the record fb_pub named in
	 * step 2, after the publication, so that on a coherent host its lines
	 * move to this core while the servo takes the commands instead of
	 * before (issue 24: the round trip was one such transfer longer). The
	 * servo answers these commands in the other buffer (fb_pub + 1); a
	 * servo two records ahead meanwhile tears the copy (TORN), as it
	 * would have torn a read before the publication.
	 * docs/amp-protocol.md section 4. */
	read_feedback(l, rx, fb_pub);

	/* The watchdog watches the heartbeat from the servo's first attach
	 * in this epoch on (check_attach), whatever its state and epoch
	 * words say since: a servo that writes FAULT (or garbage) and hangs
	 * is a stall like any other. Before that attach nothing is a stall
	 * (the servo may not have started yet). A servo that beats but whose
	 * records are refused for wd_limit cycles is as good as stalled:
	 * AMP_E_FEEDBACK, never AMP_OK (or a peer error, whose feedback
	 * callers still use) over a run of refused reads. */
	if (!l->peer_seen) {
		l->wd.primed = 0;
		return peer;
	}
	/* Stopping on request (remoteproc's stop, docs/amp-protocol.md
	 * section 3): the heartbeat ends on purpose, no stall. The watchdog
	 * starts afresh should the servo ever beat again in this epoch. */
	if (peer == AMP_E_PEER_STOPPING) {
		l->wd.primed = 0;
		return peer;
	}
	if (amp_wd_feed(&l->wd, RD(&o->servo_line.heartbeat)) == AMP_E_STALLED)
		return AMP_E_STALLED;
	if (l->fb_bad >= l->wd.limit)
		return AMP_E_FEEDBACK;
	return peer;
}

int amp_linux_mbox_post(struct amp_linux *l, const struct amp_msg *req)
{
	struct amp_frame_hdr h = { 0 };
	struct amp_ocm *o;
	uint32_t sem;
	int rc;

	if (!l || !l->ocm || !req || (req->length && !req->data))
		return AMP_E_INVAL;
	if (req->length > AMP_MBOX_CAPACITY)
		return AMP_E_NOSPC;
	o = l->ocm;
	rc = amp_linux_peer(l);
	if (rc != AMP_OK)
		return rc;
	/* 2. read the semaphore: the token must be ours. A word that is
	 * neither IDLE nor BUSY is a stray write that neither side would
	 * ever hand back: the requester takes the token (counted), and an
	 * answer still under way is told apart by its sequence. */
	AMP_PORT_CACHE_INVAL(&o->mbox_sem, 4u);
	sem = RD_ACQ(&o->mbox_sem.sem);
	if (sem == AMP_SEM_BUSY)
		return AMP_E_BUSY;
	if (sem != AMP_SEM_IDLE)
		l->st.sem_corrupt++;
	/* 1, 3. encode the frame and write it */
	h.epoch = l->epoch;
	h.seq = ++l->mbox_seq;
	h.command = req->command;
	h.length = req->length;
	amp__frame_put(&o->req, &h, req->data);
	WR(&o->linux_line.mbox_seq, h.seq);
	/* 4. set the semaphore: the servo has the token now */
	WR_REL(&o->mbox_sem.sem, AMP_SEM_BUSY);
	AMP_PORT_CACHE_CLEAN(&o->mbox_sem, 4u);
	AMP_PORT_SIGNAL();
	l->mbox_pending = 1;
	return AMP_OK;
}

int amp_linux_mbox_poll(struct amp_linux *l, struct amp_msg *resp)
{
	struct amp_frame_hdr h;
	struct amp_ocm *o;
	int rc;

	if (!l || !l->ocm || !resp || (resp->capacity && !resp->data) || !l->mbox_pending)
		return AMP_E_INVAL;
	o = l->ocm;
	/* 5. poll the semaphore until the servo has answered */
	AMP_PORT_CACHE_INVAL(&o->mbox_sem, 4u);
	if (RD_ACQ(&o->mbox_sem.sem) != AMP_SEM_IDLE) {
		rc = amp_linux_peer(l);
		return rc != AMP_OK ? rc : AMP_E_BUSY;
	}
	/* 6. read the response once, into the caller's buffer, and validate
	 * the copy (nothing is taken from OCM after the check) */
	l->mbox_pending = 0;
	rc = amp__frame_recv(&h, resp->data, resp->capacity, &o->resp, l->epoch);
	if (rc == AMP_OK && h.seq != l->mbox_seq)
		rc = AMP_E_PROTO;
	if (rc != AMP_OK) {
		l->st.mbox_err++;
		return rc;
	}
	resp->command = h.command;
	resp->status = h.status;
	resp->length = h.length;
	l->st.mbox_ok++;
	return AMP_OK;
}

int amp_linux_mbox_cancel(struct amp_linux *l)
{
	if (!l || !l->mbox_pending)
		return AMP_E_INVAL;
	l->mbox_pending = 0;
	l->st.mbox_err++;
	return AMP_OK;
}

int amp_linux_mbox_call(struct amp_linux *l, const struct amp_msg *req,
			struct amp_msg *resp, amp_ticks_t timeout)
{
	amp_ticks_t t0 = amp_port_ticks();
	int rc;

	/* An earlier request that timed out may still be with the servo:
	 * wait (within the same timeout) for it to hand the token back. */
	while ((rc = amp_linux_mbox_post(l, req)) == AMP_E_BUSY) {
		if ((amp_ticks_t)(amp_port_ticks() - t0) >= timeout)
			return AMP_E_BUSY;
		AMP_PORT_RELAX();
	}
	if (rc != AMP_OK)
		return rc;
	while ((rc = amp_linux_mbox_poll(l, resp)) == AMP_E_BUSY) {
		if ((amp_ticks_t)(amp_port_ticks() - t0) >= timeout) {
			(void)amp_linux_mbox_cancel(l);
			return AMP_E_TIMEOUT;
		}
		AMP_PORT_RELAX();
	}
	return rc;
}
