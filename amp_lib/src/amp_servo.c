// SPDX-License-Identifier: MIT
/*
 * amp_servo.c - the servo-core side of amp_lib: attach, the periodic
 * cycle (never blocks longer than the caller's timeout), and the
 * non-blocking mailbox responder. Runs bare-metal: no allocation, no
 * library calls beyond what the compiler needs.
 */
#include "amp_internal.h"

/* the later of two sequences (modulo 2^32: the one ahead of the other) */
static uint32_t seq_newest(uint32_t a, uint32_t b)
{
	return (int32_t)(b - a) > 0 ? b : a;
}

int amp_servo_attach(struct amp_servo *s, void *base, uint32_t size)
{
	struct amp_ocm *o = base;
	struct amp_servo_line *sl;
	struct amp_ocm_header h;

	if (!s || !o || ((uintptr_t)base % AMP_CACHE_LINE) != 0 || size < sizeof(*o))
		return AMP_E_INVAL;
	sl = &o->servo_line;
	AMP_PORT_CACHE_INVAL(&o->linux_line, sizeof(o->linux_line));
	if (RD_ACQ(&o->linux_line.state) != AMP_LSTATE_READY)
		return AMP_E_PEER_ABSENT;
	amp__copy_in(&h, &o->hdr, sizeof(h));
	if (h.magic != AMP_OCM_MAGIC)
		return AMP_E_PEER_ABSENT;
	if (h.version != AMP_OCM_VERSION || h.total_size != sizeof(*o) ||
	    h.max_axes != AMP_MAX_AXES || h.mbox_capacity != AMP_MBOX_CAPACITY ||
	    h.epoch == 0 || h.wd_limit == 0 || h.wd_limit > AMP_WD_LIMIT_MAX ||
	    h.crc32 != amp_crc32(0, &h, offsetof(struct amp_ocm_header, crc32)))
		return AMP_E_LAYOUT;

	*s = (struct amp_servo){ 0 };
	s->ocm = o;
	s->epoch = h.epoch;
	s->wd.limit = h.wd_limit;
	AMP_PORT_CACHE_INVAL(sl, sizeof(*sl));
	/* Linux zeroes this line with every new epoch, so continuing its
	 * sequences and counting the attach is right for a first attach (all
	 * 0) and for a re-attach in the same epoch (the servo restarted while
	 * Linux kept the region). Nothing is decided on the line's epoch
	 * word: a stray write to it must not make a restart look like a
	 * first attach (attach_count back to 1, which Linux takes for the
	 * attach it already recovered, feedback sequence back to 0, which
	 * Linux takes for reordered records). Neither side depends on the
	 * sequence words being right, though: a stray write to fb_pub while
	 * the servo was down is caught up by Linux, which resynchronises on
	 * the new attach_count (the first record of this attach is taken
	 * whatever its sequence), and the servo does the same with the
	 * commands. So that Linux can only take a record of this attach, the
	 * records of earlier ones are invalidated first (epoch word 0).
	 * The feedback sequence continues after the newest one found, in
	 * fb_pub or in either record's sequence words: a sequence written
	 * twice defeats the seqlock. The crashed attach may have written
	 * fb_pub + 1 without publishing it, or fb_pub may have gone back (a
	 * stray write) below records already published; a reader that read
	 * the old seq_end of such a record (a stray fb_pub naming it, or a
	 * read begun before the crash) would take the new payload half
	 * written. */
	s->fb_seq = RD(&sl->fb_pub);
	AMP_PORT_CACHE_INVAL(o->fb, sizeof(o->fb));
	for (uint32_t i = 0; i < 2u; i++) {
		s->fb_seq = seq_newest(s->fb_seq, RD(&o->fb[i].seq_begin));
		s->fb_seq = seq_newest(s->fb_seq, RD(&o->fb[i].seq_end));
	}
	s->heartbeat = RD(&sl->heartbeat);
	s->cmd_seq = RD_ACQ(&o->linux_line.cmd_pub);
	s->cmd_resync = 1;
	for (uint32_t i = 0; i < 2u; i++) {
		WR(&o->fb[i].epoch, 0);
		AMP_PORT_CACHE_CLEAN(&o->fb[i].epoch, 4u);
	}
	AMP_PORT_WMB();
	WR(&sl->attach_count, RD(&sl->attach_count) + 1u);
	WR(&sl->fault, 0);
	WR(&sl->cmd_stale, 0);
	WR(&sl->cmd_missed, 0);
	s->state = AMP_SSTATE_RUNNING;
	WR(&sl->state, AMP_SSTATE_RUNNING);
	WR_REL(&sl->epoch, h.epoch);
	AMP_PORT_CACHE_CLEAN(sl, sizeof(*sl));
	return AMP_OK;
}

void amp_servo_heartbeat(struct amp_servo *s)
{
	WR(&s->ocm->servo_line.heartbeat, ++s->heartbeat);
	AMP_PORT_CACHE_CLEAN(&s->ocm->servo_line, sizeof(s->ocm->servo_line));
}

void amp_servo_set_state(struct amp_servo *s, uint32_t state, uint32_t fault)
{
	struct amp_servo_line *sl = &s->ocm->servo_line;

	s->state = state;
	WR(&sl->fault, fault);
	WR_REL(&sl->state, state);
	AMP_PORT_CACHE_CLEAN(sl, sizeof(*sl));
}

int amp_servo_cycle_rx(struct amp_servo *s, amp_ticks_t timeout, struct amp_rx_info *rx)
{
	struct amp_ocm *o = s->ocm;
	amp_ticks_t t0 = 0;
	uint32_t pub, polls = 0;
	int wd;

	/* 1. the cycle is counted (the caller has cleared its interrupt
	 * flag); the heartbeat goes out with the feedback in cycle_tx, or by
	 * amp_servo_heartbeat in a cycle without exchange */
	s->cycle++;
	s->st.cycles++;
	rx->status = AMP_RX_STALE;
	rx->missed = 0;
	rx->seq = s->cmd_seq;

	AMP_PORT_CACHE_INVAL(&o->linux_line, sizeof(o->linux_line));
	AMP_PORT_CACHE_INVAL(&o->hdr, sizeof(o->hdr));
	if (RD_ACQ(&o->linux_line.state) != AMP_LSTATE_READY ||
	    RD(&o->hdr.epoch) != s->epoch) {
		s->st.stale++;
		return AMP_E_PEER_ABSENT;	/* closed or re-initialised */
	}
	wd = amp_wd_feed(&s->wd, RD(&o->linux_line.heartbeat));

	/* 2. poll the semaphore (or a newer sequence), bounded by timeout */
	for (;;) {
		AMP_PORT_CACHE_INVAL(&o->cyc_sem, 4u);
		AMP_PORT_CACHE_INVAL(&o->linux_line, sizeof(o->linux_line));
		pub = RD_ACQ(&o->linux_line.cmd_pub);
		if (pub != s->cmd_seq || RD_ACQ(&o->cyc_sem.sem) == AMP_SEM_BUSY)
			break;
		/* the clock is read only when there is something to wait for */
		if (timeout == 0)
			break;
		if (polls++ == 0)
			t0 = amp_port_ticks();
		else if ((amp_ticks_t)(amp_port_ticks() - t0) >= timeout)
			break;
		AMP_PORT_RELAX();
	}

	/* 3. switch the command buffer: read the newest commands */
	if (amp__rx_record(&s->cmd, 0, o->cmd, CMD_WORDS, CMD_END, CMD_NAXES, CMD_SLOT,
			   pub, s->cmd_seq, s->epoch, &s->cmd_resync, rx, &s->st))
		s->cmd_seq = pub;
	if (rx->status != AMP_RX_FRESH) {
		WR(&o->servo_line.cmd_stale, s->st.stale + s->st.torn + s->st.invalid);
		WR(&o->servo_line.cmd_missed, s->st.missed);
	}
	return wd;
}

int amp_servo_cycle_tx(struct amp_servo *s, const struct amp_fb_axis *axes,
		       uint32_t n_axes, uint32_t t_cycle, uint32_t irq_latency)
{
	struct amp_ocm *o = s->ocm;
	uint32_t h[AMP_REC_HDR_WORDS];	/* words 1..7, each set below (no memset) */
	uint32_t seq;

	if (n_axes > AMP_MAX_AXES || (n_axes && !axes))
		return AMP_E_INVAL;
	/* 4. switch the response buffer: write and publish the feedback */
	/* (the record's header, then the caller's n_axes slots straight to
	 * OCM: no record built in private memory first) */
	h[AMP_REC_W(struct amp_fb_record, epoch)] = s->epoch;
	/* the last commands this servo took: none yet since its attach is 0,
	 * not the cmd_pub it found there (commands it never took) */
	h[AMP_REC_W(struct amp_fb_record, cmd_seq)] = s->cmd_resync ? 0u : s->cmd_seq;
	h[AMP_REC_W(struct amp_fb_record, cycle)] = s->cycle;
	h[AMP_REC_W(struct amp_fb_record, t_cycle)] = t_cycle;
	h[AMP_REC_W(struct amp_fb_record, irq_latency)] = irq_latency;
	h[FB_NAXES] = n_axes;
	/* the state this servo last wrote, not read back from its line: a
	 * read of the line that Linux's semaphore write just took away would
	 * be one more cross-core transfer before the line is written below */
	h[AMP_REC_W(struct amp_fb_record, status)] = s->state;
	seq = s->fb_seq + 1u;
	amp__rec_write(&o->fb[seq & 1u], h, axes, n_axes * FB_SLOT, FB_END, seq);
	WR(&o->servo_line.heartbeat, ++s->heartbeat);
	WR_REL(&o->servo_line.fb_pub, seq);
	AMP_PORT_CACHE_CLEAN(&o->servo_line, sizeof(o->servo_line));
	s->fb_seq = seq;

	/* 5. hand the semaphore back (idle) if we hold the token */
	AMP_PORT_CACHE_INVAL(&o->cyc_sem, 4u);
	if (RD_ACQ(&o->cyc_sem.sem) == AMP_SEM_BUSY) {
		WR_REL(&o->cyc_sem.sem, AMP_SEM_IDLE);
		AMP_PORT_CACHE_CLEAN(&o->cyc_sem, 4u);
	}
	AMP_PORT_SIGNAL();
	return AMP_OK;
}

static void mbox_answer(struct amp_servo *s, int32_t status,
			const void *payload, uint32_t len)
{
	struct amp_frame_hdr h = { 0 };

	h.epoch = s->epoch;
	h.seq = s->mbox_seq;
	h.command = s->mbox_cmd;
	h.status = status;
	h.length = len;
	amp__frame_put(&s->ocm->resp, &h, payload);
	s->mbox_state = 0;
	/* 5. set the semaphore: the response is complete */
	WR_REL(&s->ocm->mbox_sem.sem, AMP_SEM_IDLE);
	AMP_PORT_CACHE_CLEAN(&s->ocm->mbox_sem, 4u);
	AMP_PORT_SIGNAL();
}

int amp_servo_mbox_poll(struct amp_servo *s, struct amp_mbox_req *req)
{
	struct amp_ocm *o = s->ocm;
	struct amp_frame_hdr h;
	int rc;

	if (s->mbox_state)
		return 0;	/* the request handed out is still unanswered */
	/* 1. poll the semaphore: busy means Linux has posted a request */
	AMP_PORT_CACHE_INVAL(&o->mbox_sem, 4u);
	if (RD_ACQ(&o->mbox_sem.sem) != AMP_SEM_BUSY)
		return 0;
	/* 2. read the request once into private memory, every field of the
	 * copy validated; the application gets the copy */
	rc = amp__frame_recv(&h, s->req_buf, sizeof(s->req_buf), &o->req, s->epoch);
	s->mbox_seq = h.seq;
	s->mbox_cmd = h.command;
	if (rc != AMP_OK) {
		s->st.mbox_err++;
		mbox_answer(s, AMP_E_PROTO, 0, 0);
		return AMP_E_PROTO;
	}
	s->mbox_state = 1;
	s->st.mbox_ok++;
	req->command = h.command;
	req->length = h.length;
	req->payload = (const uint8_t *)s->req_buf;
	return 1;
}

int amp_servo_mbox_respond(struct amp_servo *s, int32_t status,
			   const void *payload, uint32_t len)
{
	if (!s->mbox_state || (len && !payload))
		return AMP_E_INVAL;
	if (len > AMP_MBOX_CAPACITY)
		return AMP_E_NOSPC;
	mbox_answer(s, status, payload, len);
	return AMP_OK;
}
