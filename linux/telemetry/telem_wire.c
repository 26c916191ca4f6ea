// SPDX-License-Identifier: MIT
/*
 * telem_wire.c - the encoding of the messages the drain thread sends
 * (CYCLE, GAP, HELLO, REPLY; docs/telemetry.md). The little-endian
 * field encoders (put16 .. putstr, frame) are in telem_internal.h.
 */
#define _GNU_SOURCE
#include "telem_internal.h"

#include <time.h>

uint64_t telem__realtime_ns(void)
{
	struct timespec ts;

	clock_gettime(CLOCK_REALTIME, &ts);
	return (uint64_t)ts.tv_sec * 1000000000ull + (uint64_t)ts.tv_nsec;
}

unsigned char *telem__enc_gap(unsigned char *p, uint64_t t_ns, uint64_t from, uint64_t to,
			      uint64_t count, uint32_t reason)
{
	p = frame(p, TELEM_MSG_GAP, GAP_LEN);
	p = put64(p, t_ns);
	p = put64(p, from);
	p = put64(p, to);
	p = put64(p, count);
	p = put32(p, reason);
	return put32(p, 0);
}

size_t telem__enc_hello(struct telem *t, unsigned char *b)
{
	unsigned char *p = frame(b, TELEM_MSG_HELLO, HELLO_LEN);

	p = put32(p, TELEM_MAGIC);
	p = put16(p, TELEM_WIRE_VERSION);
	p = put16(p, 0);
	p = put64(p, t->session_id);
	p = put64(p, mono_now_ns());
	p = put64(p, telem__realtime_ns());
	p = put32(p, t->cfg.n_axes);
	p = put32(p, t->cfg.cycle_period_ns);
	p = put32(p, t->cfg.clock_hz);
	p = put32(p, t->cfg.ring_capacity);
	p = putstr(p, t->controller_id, TELEM_ID_LEN);
	return (size_t)(p - b);
}

size_t telem__enc_reply(unsigned char *b, uint32_t id, int32_t status, const char *text, size_t len)
{
	unsigned char *p = b;

	if (len > TELEM_REPLY_MAX)
		len = TELEM_REPLY_MAX;
	p = frame(p, TELEM_MSG_REPLY, REPLY_HDR + (uint32_t)len);
	p = put32(p, id);
	p = puti32(p, status);
	p = put32(p, (uint32_t)len);
	memcpy(p, text, len);
	return (size_t)(p - b) + len;
}

size_t telem__enc_cycle(struct telem *t, unsigned char *b, const struct telem_cycle *c)
{
	uint32_t n = t->cfg.n_axes;
	unsigned char *p = frame(b, TELEM_MSG_CYCLE, CYCLE_HDR_LEN + AXIS_LEN * n);

	p = put64(p, c->cycle);
	p = put64(p, c->t_ns);
	p = put32(p, c->servo_cycle);
	p = put32(p, c->t_cycle);
	p = put32(p, c->irq_latency);
	p = put32(p, c->wake_latency_ns);
	p = put32(p, c->exchange);
	p = put32(p, c->missed);
	p = put32(p, c->servo_status);
	p = puti32(p, c->result);
	p = put32(p, c->n_axes < n ? c->n_axes : n);	/* axes with data */
	for (uint32_t i = 0; i < n; i++) {
		static const struct amp_cmd_axis zc;
		static const struct amp_fb_axis zf;
		const struct amp_cmd_axis *a = i < c->n_axes ? &c->cmd[i] : &zc;
		const struct amp_fb_axis *f = i < c->n_axes ? &c->fb[i] : &zf;

		p = put32(p, a->control_word);
		p = puti32(p, a->target_pos);
		p = puti32(p, a->vel_ff);
		p = puti32(p, a->torque_offset);
		p = put32(p, f->status_word);
		p = puti32(p, f->actual_pos);
		p = puti32(p, f->actual_vel);
		p = puti32(p, f->current);
		p = puti32(p, f->following_error);
	}
	return (size_t)(p - b);
}
