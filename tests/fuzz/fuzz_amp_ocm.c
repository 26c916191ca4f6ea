// SPDX-License-Identifier: MIT
/*
 * fuzz_amp_ocm - amp_lib's receiving side, Linux's and the servo's, with
 * the fuzzer as the peer. The input is a small program of operations:
 * the peer writes any word or byte run of the shared region (also between
 * two loads of one call: a "tamper" armed for the k-th load from OCM),
 * or makes a frame / header / record look valid (so the fuzzer gets past
 * CRCs and sequences), and each side runs its real receiving calls:
 *
 *   Linux: amp_linux_init, _cycle (feedback read), _mbox_post / _poll /
 *          _call (response), _peer, _peer_info, _set_wd_limit
 *   servo: amp_servo_attach, _cycle_rx (command read), _cycle_tx,
 *          _mbox_poll (request) / _respond
 *
 * After every call the harness asserts what amp.h and docs/amp-protocol.md
 * promise whatever the peer wrote: return codes from the documented set,
 * rx status and sequences consistent, every record held with an axis
 * count <= AMP_MAX_AXES and the receiver's epoch, mailbox lengths within
 * the capacity and the caller's buffer (a heap buffer of exactly that size:
 * ASan sees one byte more), a request payload inside the OCM frame, and an
 * answer that is the frame whose CRC was checked. Time is the port's tick
 * counter (one tick per poll): nothing may wait forever.
 */
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "amp/amp.h"

#define WORDS (AMP_OCM_SIZE / 4u)

static struct amp_ocm ocm;
static uint32_t *const ow = (uint32_t *)&ocm;
static uint32_t last_read[WORDS];	/* value each OCM word was last loaded as */
static uint32_t ticks;
static uint32_t loads;
static uint32_t tamper_at;		/* 0 = none, else the load number */
static uint32_t tamper_val;

#include "fuzz_assert.h"

uint32_t fz_load(const volatile uint32_t *p)
{
	uintptr_t a = (uintptr_t)p, b = (uintptr_t)&ocm;
	uint32_t v;

	if (a < b || a >= b + sizeof(ocm))
		return *p;
	loads++;
	if (tamper_at && loads == tamper_at) {
		*(volatile uint32_t *)p = tamper_val;	/* the peer writes now */
		tamper_at = 0;
	}
	v = *p;
	last_read[(a - b) / 4u] = v;
	return v;
}

uint32_t fz_ticks(void)
{
	return ticks++;
}

/* ---- input ---------------------------------------------------------- */
struct in {
	const uint8_t *p;
	size_t n;
};

static uint8_t u8(struct in *in)
{
	uint8_t v = 0;

	if (in->n) {
		v = *in->p++;
		in->n--;
	}
	return v;
}

static uint16_t u16(struct in *in)
{
	return (uint16_t)(u8(in) | (uint16_t)u8(in) << 8);
}

static uint32_t u32(struct in *in)
{
	return (uint32_t)u16(in) | (uint32_t)u16(in) << 16;
}

/* ---- helpers of the peer: valid-looking frames and records ---------- */
static void fix_frame(struct amp_frame *f)
{
	struct amp_frame_hdr h;

	memcpy(&h, (const void *)&f->hdr, sizeof(h));
	if (h.length > AMP_MBOX_CAPACITY)
		return;
	h.crc32 = 0;
	f->hdr.crc32 = amp_crc32(amp_crc32(0, &h, sizeof(h)), f->payload, h.length);
}

static void fix_header(void)
{
	ocm.hdr.crc32 = amp_crc32(0, &ocm.hdr, offsetof(struct amp_ocm_header, crc32));
}

/* The CRC a frame with these header fields and this payload carries. */
static uint32_t frame_crc(uint32_t epoch, uint32_t seq, uint32_t command,
			  int32_t status, uint32_t len, const void *data)
{
	struct amp_frame_hdr h = {
		.magic = AMP_FRAME_MAGIC, .version = AMP_OCM_VERSION,
		.epoch = epoch, .seq = seq, .command = command,
		.status = status, .length = len, .crc32 = 0,
	};

	return amp_crc32(amp_crc32(0, &h, sizeof(h)), data, len);
}

/* ---- the two sides -------------------------------------------------- */
static struct amp_linux l;
static struct amp_servo s;
static int l_up, s_up;

static int is_rx_status(uint32_t st)
{
	return st <= AMP_RX_INVALID;
}

static void check_rx(const struct amp_rx_info *rx, uint32_t held_seq)
{
	FZ_ASSERT(is_rx_status(rx->status));
	FZ_ASSERT(rx->status == AMP_RX_MISSED ? rx->missed > 0 : rx->missed == 0);
	FZ_ASSERT(rx->seq == held_seq);
}

static void check_linux(void)
{
	FZ_ASSERT(l.fb.n_axes <= AMP_MAX_AXES);
	FZ_ASSERT(l.fb_seq == 0 || l.fb.epoch == l.epoch);
	FZ_ASSERT(l.wd.limit >= 1 && l.wd.limit <= 1000000u);
	FZ_ASSERT(l.wd.still <= 1000000u);
}

static void check_servo(void)
{
	FZ_ASSERT(s.cmd.n_axes <= AMP_MAX_AXES);
	FZ_ASSERT(s.cmd.epoch == 0 || s.cmd.epoch == s.epoch);
	FZ_ASSERT(s.epoch != 0);
	FZ_ASSERT(s.wd.limit >= 1 && s.wd.limit <= 1000000u);
	FZ_ASSERT(s.wd.still <= s.wd.limit); /* the servo's limit never changes */
	FZ_ASSERT(s.mbox_state <= 1);
}

static void op_linux_cycle(struct in *in)
{
	struct amp_cmd_axis ax[AMP_MAX_AXES];
	struct amp_rx_info rx;
	uint32_t n = u8(in) % (AMP_MAX_AXES + 1u), prev = l.fb_seq, bad = l.fb_bad;
	uint32_t resync = l.fb_resync, attach = l.servo_attach, seen = l.peer_seen;
	int rc;

	memset(ax, 0x5a, sizeof(ax));
	rc = amp_linux_cycle(&l, ax, n, u8(in), &rx);
	/* (a servo whose state word says STOPPING: AMP_E_PEER_STOPPING, never
	 * a stall; docs/amp-protocol.md section 3) */
	FZ_ASSERT(rc == AMP_OK || rc == AMP_E_PEER_ABSENT || rc == AMP_E_PEER_ERROR ||
		  rc == AMP_E_STALLED || rc == AMP_E_FEEDBACK || rc == AMP_E_PEER_STOPPING);
	check_rx(&rx, l.fb_seq);
	/* refused reads are never AMP_OK (nor a peer error) for wd_limit
	 * cycles: once the servo has attached, AMP_E_FEEDBACK at the latest */
	FZ_ASSERT(l.fb_bad <= bad + 1u);
	if (l.peer_seen && l.fb_bad >= l.wd.limit)
		FZ_ASSERT(rc == AMP_E_STALLED || rc == AMP_E_FEEDBACK || rc == AMP_E_PEER_STOPPING);
	if (rx.status == AMP_RX_FRESH || rx.status == AMP_RX_MISSED) {
		/* in sequence, or the first record after an attach seen now
		 * or earlier (any sequence, FRESH) */
		resync = resync || l.servo_attach != attach || (!seen && l.peer_seen);
		FZ_ASSERT(l.fb_seq - prev == rx.missed + 1u ||
			  (resync && rx.status == AMP_RX_FRESH && rx.missed == 0));
		FZ_ASSERT(l.fb_bad == 0 && !l.fb_resync);
		FZ_ASSERT(l.fb.epoch == l.epoch);
		FZ_ASSERT(l.fb.seq_begin == l.fb_seq && l.fb.seq_end == l.fb_seq);
	} else {
		FZ_ASSERT(l.fb_seq == prev);
	}
	/* the commands just published are Linux's own, whole */
	FZ_ASSERT(ocm.linux_line.cmd_pub == l.cmd_seq);
	check_linux();
}

static uint8_t req_data[AMP_MBOX_CAPACITY];

static void check_answer(const struct amp_msg *resp, uint32_t cap)
{
	FZ_ASSERT(resp->length <= cap && resp->length <= AMP_MBOX_CAPACITY);
	/* the answer handed over is the frame whose CRC was checked: header
	 * fields and payload as returned, against the CRC word as read */
	FZ_ASSERT(frame_crc(l.epoch, l.mbox_seq, resp->command, resp->status,
			    resp->length, resp->data) ==
		  last_read[offsetof(struct amp_ocm, resp.hdr.crc32) / 4u]);
}

static void op_linux_poll(struct in *in, int call)
{
	uint32_t cap = u16(in) % (AMP_MBOX_CAPACITY + 1u);
	uint8_t *buf = malloc(cap ? cap : 1u);	/* exactly cap bytes */
	struct amp_msg resp = { .capacity = cap, .data = buf };
	int rc;

	FZ_ASSERT(buf);
	if (call) {
		struct amp_msg req = { .command = u32(in), .length = u16(in) % 64u,
				       .data = req_data };

		rc = amp_linux_mbox_call(&l, &req, &resp, u8(in));
		FZ_ASSERT(rc == AMP_OK || rc == AMP_E_PEER_ABSENT || rc == AMP_E_PEER_ERROR ||
			  rc == AMP_E_BUSY || rc == AMP_E_TIMEOUT || rc == AMP_E_PROTO ||
			  rc == AMP_E_NOSPC || rc == AMP_E_PEER_STOPPING);
	} else {
		rc = amp_linux_mbox_poll(&l, &resp);
		FZ_ASSERT(rc == AMP_OK || rc == AMP_E_PEER_ABSENT || rc == AMP_E_PEER_ERROR ||
			  rc == AMP_E_BUSY || rc == AMP_E_PROTO || rc == AMP_E_NOSPC ||
			  rc == AMP_E_INVAL || rc == AMP_E_PEER_STOPPING);
		FZ_ASSERT(rc != AMP_E_INVAL || !l.mbox_pending);
	}
	if (rc == AMP_OK)
		check_answer(&resp, cap);
	/* the request stays out only while the servo holds the token */
	if (rc != AMP_E_BUSY && rc != AMP_E_PEER_ABSENT && rc != AMP_E_PEER_ERROR)
		FZ_ASSERT(!l.mbox_pending);
	free(buf);
	check_linux();
}

static void op_linux_post(struct in *in)
{
	struct amp_msg req = { .command = u32(in) };
	int rc;

	req.length = u16(in) % (AMP_MBOX_CAPACITY + 1u);
	req.data = req_data;
	if (l.mbox_pending)
		(void)amp_linux_mbox_cancel(&l);
	rc = amp_linux_mbox_post(&l, &req);
	FZ_ASSERT(rc == AMP_OK || rc == AMP_E_PEER_ABSENT || rc == AMP_E_PEER_ERROR ||
		  rc == AMP_E_BUSY || rc == AMP_E_PEER_STOPPING);
	FZ_ASSERT((rc == AMP_OK) == (l.mbox_pending == 1));
	check_linux();
}

static void op_linux_peer(void)
{
	struct amp_peer_info pi;
	int rc = amp_linux_peer(&l);

	FZ_ASSERT(rc == AMP_OK || rc == AMP_E_PEER_ABSENT || rc == AMP_E_PEER_ERROR ||
		  rc == AMP_E_PEER_STOPPING);
	FZ_ASSERT(amp_linux_peer_info(&ocm, sizeof(ocm), &pi) == AMP_OK);
	FZ_ASSERT(amp_linux_peer_info(&ocm, sizeof(ocm) - 4u, &pi) == AMP_E_INVAL);
}

static void op_servo_attach(void)
{
	struct amp_servo t;
	int rc = amp_servo_attach(&t, &ocm, sizeof(ocm));

	FZ_ASSERT(rc == AMP_OK || rc == AMP_E_PEER_ABSENT || rc == AMP_E_LAYOUT);
	if (rc == AMP_OK) {
		s = t;
		s_up = 1;
		FZ_ASSERT(ocm.servo_line.epoch == s.epoch);
		check_servo();
	}
}

static void op_servo_rx(struct in *in)
{
	struct amp_rx_info rx;
	uint32_t prev = s.cmd_seq, resync = s.cmd_resync;
	int rc = amp_servo_cycle_rx(&s, u8(in), &rx);

	FZ_ASSERT(rc == AMP_OK || rc == AMP_E_STALLED || rc == AMP_E_PEER_ABSENT);
	check_rx(&rx, s.cmd_seq);
	if (rx.status == AMP_RX_FRESH || rx.status == AMP_RX_MISSED) {
		/* in sequence, or the first commands after the attach (any
		 * sequence, FRESH) */
		FZ_ASSERT(s.cmd_seq - prev == rx.missed + 1u ||
			  (resync && rx.status == AMP_RX_FRESH && rx.missed == 0));
		FZ_ASSERT(!s.cmd_resync);
		FZ_ASSERT(s.cmd.epoch == s.epoch);
		FZ_ASSERT(s.cmd.seq_begin == s.cmd_seq && s.cmd.seq_end == s.cmd_seq);
	} else {
		FZ_ASSERT(s.cmd_seq == prev);
	}
	check_servo();
}

static void op_servo_tx(struct in *in)
{
	struct amp_fb_axis ax[AMP_MAX_AXES];
	uint32_t n = u8(in) % (AMP_MAX_AXES + 1u);

	memset(ax, 0xa5, sizeof(ax));
	FZ_ASSERT(amp_servo_cycle_tx(&s, ax, n, u32(in), u32(in)) == AMP_OK);
	FZ_ASSERT(ocm.servo_line.fb_pub == s.fb_seq);
	check_servo();
}

static void op_servo_poll(struct in *in)
{
	struct amp_mbox_req req;
	uint8_t answer[AMP_MBOX_CAPACITY];
	int rc = amp_servo_mbox_poll(&s, &req);

	FZ_ASSERT(rc == 0 || rc == 1 || rc == AMP_E_PROTO);
	if (rc == 1) {
		uint32_t len;

		FZ_ASSERT(req.length <= AMP_MBOX_CAPACITY);
		/* the validated private copy, never the payload in OCM */
		FZ_ASSERT(req.payload == (const volatile uint8_t *)s.req_buf);
		FZ_ASSERT(s.mbox_state == 1);
		/* what the application does: read the payload it was handed */
		for (uint32_t i = 0; i < req.length; i++)
			answer[i] = req.payload[i];
		len = u16(in) % (AMP_MBOX_CAPACITY + 1u);
		if (len > req.length)
			memset(answer + req.length, 0, len - req.length);
		FZ_ASSERT(amp_servo_mbox_respond(&s, (int32_t)u32(in), answer, len) == AMP_OK);
		FZ_ASSERT(s.mbox_state == 0);
	}
	if (rc == AMP_E_PROTO) {
		/* answered at once with AMP_E_PROTO, token handed back */
		FZ_ASSERT(ocm.mbox_sem.sem == AMP_SEM_IDLE);
		FZ_ASSERT(ocm.resp.hdr.status == AMP_E_PROTO && ocm.resp.hdr.length == 0);
	}
	check_servo();
}

/* The peer writes a whole, valid-looking feedback (Linux reads it) or
 * command (the servo reads it) record with a chosen sequence step and
 * axis count. */
static void op_peer_record(struct in *in)
{
	uint8_t which = u8(in);
	uint32_t step = u8(in), n = u8(in);

	if (which & 1u) {
		uint32_t seq = ocm.servo_line.fb_pub + step;
		struct amp_fb_record *f = &ocm.fb[seq & 1u];

		f->seq_begin = f->seq_end = seq;
		f->epoch = (which & 2u) ? u32(in) : l.epoch;
		f->n_axes = n;
		ocm.servo_line.fb_pub = seq;
	} else {
		uint32_t seq = ocm.linux_line.cmd_pub + step;
		struct amp_cmd_record *c = &ocm.cmd[seq & 1u];

		c->seq_begin = c->seq_end = seq;
		c->epoch = (which & 2u) ? u32(in) : ocm.hdr.epoch;
		c->n_axes = n;
		ocm.linux_line.cmd_pub = seq;
		ocm.cyc_sem.sem = AMP_SEM_BUSY;
	}
}

/* The peer answers Linux's request (servo side of the mailbox, by hand). */
static void op_peer_answer(struct in *in)
{
	uint32_t len = u16(in) % (AMP_MBOX_CAPACITY + 64u);

	ocm.resp.hdr.magic = AMP_FRAME_MAGIC;
	ocm.resp.hdr.version = AMP_OCM_VERSION;
	ocm.resp.hdr.epoch = l.epoch;
	ocm.resp.hdr.seq = ocm.req.hdr.seq;
	ocm.resp.hdr.command = ocm.req.hdr.command;
	ocm.resp.hdr.status = (int32_t)u32(in);
	ocm.resp.hdr.length = len;
	for (uint32_t i = 0; i < len && i < AMP_MBOX_CAPACITY; i++)
		ocm.resp.payload[i] = u8(in);
	fix_frame(&ocm.resp);
	ocm.mbox_sem.sem = AMP_SEM_IDLE;
}

enum {
	OP_WORD, OP_BYTES, OP_TAMPER, OP_FIX_HDR, OP_FIX_REQ, OP_FIX_RESP,
	OP_RECORD, OP_ANSWER,
	OP_L_INIT, OP_L_CYCLE, OP_L_POST, OP_L_POLL, OP_L_CALL, OP_L_PEER,
	OP_L_WD,
	OP_S_ATTACH, OP_S_RX, OP_S_TX, OP_S_POLL, OP_S_STATE,
	OP_NUM
};

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	struct in in = { data, size };
	unsigned steps = 0;

	memset(&ocm, 0, sizeof(ocm));
	memset(last_read, 0, sizeof(last_read));
	memset(&l, 0, sizeof(l));
	memset(&s, 0, sizeof(s));
	memset(req_data, 0x3c, sizeof(req_data));
	l_up = s_up = 0;
	ticks = loads = tamper_at = 0;

	/* Linux initialises the region first, as servod does */
	FZ_ASSERT(amp_linux_init(&l, &ocm, sizeof(ocm), 0) == AMP_OK);
	l_up = 1;

	while (in.n && steps++ < 256u) {
		uint8_t op = u8(&in) % OP_NUM;

		switch (op) {
		case OP_WORD: {
			uint32_t i = u16(&in) % WORDS;

			ow[i] = u32(&in);
			break;
		}
		case OP_BYTES: {
			uint32_t off = u16(&in) % sizeof(ocm), n = u8(&in);

			for (uint32_t i = 0; i < n && off + i < sizeof(ocm); i++)
				((uint8_t *)&ocm)[off + i] = u8(&in);
			break;
		}
		case OP_TAMPER:
			tamper_at = loads + 1u + u8(&in);
			tamper_val = u32(&in);
			break;
		case OP_FIX_HDR:
			fix_header();
			break;
		case OP_FIX_REQ:
			fix_frame(&ocm.req);
			break;
		case OP_FIX_RESP:
			fix_frame(&ocm.resp);
			break;
		case OP_RECORD:
			op_peer_record(&in);
			break;
		case OP_ANSWER:
			op_peer_answer(&in);
			break;
		case OP_L_INIT:
			FZ_ASSERT(amp_linux_init(&l, &ocm, sizeof(ocm), u8(&in)) == AMP_OK);
			FZ_ASSERT(l.epoch != 0 && ocm.hdr.epoch == l.epoch);
			break;
		case OP_L_CYCLE:
			op_linux_cycle(&in);
			break;
		case OP_L_POST:
			op_linux_post(&in);
			break;
		case OP_L_POLL:
			op_linux_poll(&in, 0);
			break;
		case OP_L_CALL:
			op_linux_poll(&in, 1);
			break;
		case OP_L_PEER:
			op_linux_peer();
			break;
		case OP_L_WD:
			FZ_ASSERT(amp_linux_set_wd_limit(&l, u8(&in)) == AMP_OK);
			break;
		case OP_S_ATTACH:
			op_servo_attach();
			break;
		case OP_S_RX:
			if (s_up)
				op_servo_rx(&in);
			break;
		case OP_S_TX:
			if (s_up)
				op_servo_tx(&in);
			break;
		case OP_S_POLL:
			if (s_up)
				op_servo_poll(&in);
			break;
		case OP_S_STATE:
			if (s_up)
				amp_servo_set_state(&s, u32(&in), u32(&in));
			break;
		}
	}
	(void)l_up;
	return 0;
}
