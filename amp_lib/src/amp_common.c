// SPDX-License-Identifier: MIT
/* amp_common.c - CRC, watchdog and record helpers used by both sides. */
#include "amp_internal.h"

uint32_t amp_crc32(uint32_t crc, const void *data, uint32_t len)
{
	/* Nibble table: 64 bytes instead of 1 KiB, fine for the mailbox. */
	static const uint32_t t[16] = {
		0x00000000u, 0x1db71064u, 0x3b6e20c8u, 0x26d930acu,
		0x76dc4190u, 0x6b6b51f4u, 0x4db26158u, 0x5005713cu,
		0xedb88320u, 0xf00f9344u, 0xd6d6a3e8u, 0xcb61b38cu,
		0x9b64c2b0u, 0x86d3d2d4u, 0xa00ae278u, 0xbdbdf21cu,
	};
	const uint8_t *p = data;	/* private memory only: never OCM */

	crc = ~crc;
	while (len--) {
		crc ^= *p++;
		crc = (crc >> 4) ^ t[crc & 15u];
		crc = (crc >> 4) ^ t[crc & 15u];
	}
	return ~crc;
}

int amp_wd_feed(struct amp_watchdog *wd, uint32_t hb)
{
	if (!wd->primed || hb != wd->last) {
		wd->last = hb;
		wd->still = 0;
		wd->primed = 1;
		return AMP_OK;
	}
	if (wd->still < wd->limit)
		wd->still++;
	return wd->still >= wd->limit ? AMP_E_STALLED : AMP_OK;
}

void amp__copy_in(void *dst, const void *ocm_src, uint32_t bytes)
{
	uint32_t *d = dst;
	const uint32_t *s = ocm_src;

	AMP_PORT_CACHE_INVAL(ocm_src, bytes);
	for (uint32_t i = 0; i < bytes / 4u; i++)
		d[i] = RD(&s[i]);
}

void amp__copy_out(void *ocm_dst, const void *src, uint32_t bytes)
{
	uint32_t *d = ocm_dst;
	const uint32_t *s = src;

	for (uint32_t i = 0; i < bytes / 4u; i++)
		WR(&d[i], s[i]);
	AMP_PORT_CACHE_CLEAN(ocm_dst, bytes);
}

void amp__rec_write(void *ocm_rec, const void *src, uint32_t words,
		    uint32_t end, uint32_t seq)
{
	uint32_t *d = ocm_rec;
	const uint32_t *s = src;

	WR(&d[0], seq);
	AMP_PORT_CACHE_CLEAN(d, 4u);
	AMP_PORT_WMB();
	for (uint32_t i = 1; i < words; i++)
		if (i != end)
			WR(&d[i], s[i]);
	AMP_PORT_CACHE_CLEAN(d, words * 4u);
	AMP_PORT_WMB();
	WR(&d[end], seq);
	AMP_PORT_CACHE_CLEAN(&d[end], 4u);
	/* the caller publishes seq with a release store */
}

int amp__rec_read(void *dst, const void *ocm_rec, uint32_t words,
		  uint32_t end, uint32_t seq)
{
	uint32_t *d = dst;
	const uint32_t *s = ocm_rec;
	uint32_t e, b;

	AMP_PORT_CACHE_INVAL(s, words * 4u);
	e = RD(&s[end]);
	AMP_PORT_RMB();
	for (uint32_t i = 1; i < words; i++)
		if (i != end)
			d[i] = RD(&s[i]);
	AMP_PORT_RMB();
	AMP_PORT_CACHE_INVAL(s, 4u);
	b = RD(&s[0]);
	d[0] = b;
	d[end] = e;
	return (b == e && e == seq) ? 0 : -1;
}

uint32_t amp__rx_classify(uint32_t pub, uint32_t last, uint32_t *missed)
{
	int32_t d = (int32_t)(pub - last);

	*missed = 0;
	if (d == 0)
		return AMP_RX_STALE;
	if (d < 0)
		return AMP_RX_INVALID;	/* went backwards: reordered */
	if (d == 1)
		return AMP_RX_FRESH;
	*missed = (uint32_t)d - 1u;
	return AMP_RX_MISSED;
}

static int words_equal(const uint32_t *a, const uint32_t *b, uint32_t words)
{
	for (uint32_t i = 0; i < words; i++)
		if (a[i] != b[i])
			return 0;
	return 1;
}

int amp__rx_record(void *tmp, const void *bufs, uint32_t words, uint32_t end,
		   uint32_t naxes_word, uint32_t pub, uint32_t last, uint32_t epoch,
		   uint32_t *resync, const void *held, struct amp_rx_info *rx,
		   struct amp_stats *st)
{
	const uint32_t *rec = (const uint32_t *)bufs + (pub & 1u) * words;
	const uint32_t *t = tmp;
	int take = 0;

	rx->status = amp__rx_classify(pub, last, &rx->missed);
	/* Resynchronising (the peer attached anew): its sequence owes
	 * nothing to the last one read, so the published one names the
	 * record to check, ahead, behind or even equal, and its distance
	 * is no count of skipped records. */
	if (*resync) {
		rx->status = AMP_RX_FRESH;
		rx->missed = 0;
	}
	if (rx->status == AMP_RX_FRESH || rx->status == AMP_RX_MISSED) {
		if (amp__rec_read(tmp, rec, words, end, pub) != 0)
			rx->status = AMP_RX_TORN;
		else if (t[1] != epoch || t[naxes_word] > AMP_MAX_AXES)
			rx->status = AMP_RX_INVALID;
		else if (held && words_equal(t, held, words))
			/* word for word the record the reader holds, read again
			 * while resynchronising (the attach seen a cycle after
			 * its first record was taken, or attach_count hit by a
			 * stray write): nothing new. (Without resynchronising
			 * pub != last here, so the sequence words differ and
			 * this stops at word 0.) */
			rx->status = AMP_RX_STALE;
		else
			take = 1;
		if (!take) {
			rx->missed = 0;
			/* the last sequence read, not yet rewritten: nothing new */
			if (pub == last)
				rx->status = AMP_RX_STALE;
		}
	}
	if (take)
		*resync = 0;
	rx->seq = take ? pub : last;
	switch (rx->status) {
	case AMP_RX_FRESH: st->fresh++; break;
	case AMP_RX_MISSED: st->fresh++; st->missed += rx->missed; break;
	case AMP_RX_STALE: st->stale++; break;
	case AMP_RX_TORN: st->torn++; break;
	default: st->invalid++; break;
	}
	return take;
}

void amp__bytes_in(void *dst, const void *ocm_src, uint32_t len)
{
	uint8_t *d = dst;
	const uint32_t *s = ocm_src;

	AMP_PORT_CACHE_INVAL(ocm_src, len);
	for (uint32_t i = 0; i < len; i += 4u) {
		uint32_t w = RD(&s[i / 4u]);

		for (uint32_t b = 0; b < 4u && i + b < len; b++)
			d[i + b] = (uint8_t)(w >> (8u * b));
	}
}

void amp__bytes_out(void *ocm_dst, const void *src, uint32_t len)
{
	uint32_t *d = ocm_dst;
	const uint8_t *s = src;

	for (uint32_t i = 0; i < len; i += 4u) {
		uint32_t w = 0;

		for (uint32_t b = 0; b < 4u && i + b < len; b++)
			w |= (uint32_t)s[i + b] << (8u * b);
		WR(&d[i / 4u], w);
	}
	AMP_PORT_CACHE_CLEAN(ocm_dst, len);
}

static uint32_t frame_crc(const struct amp_frame_hdr *h, const void *payload)
{
	struct amp_frame_hdr c = *h;

	c.crc32 = 0;
	return amp_crc32(amp_crc32(0, &c, sizeof(c)), payload, h->length);
}

int amp__frame_recv(struct amp_frame_hdr *h, void *payload, uint32_t cap,
		    const struct amp_frame *f, uint32_t epoch)
{
	/* One copy of the header, then (its length checked on the copy) one
	 * copy of the payload; the CRC is computed over the copies. The peer
	 * may rewrite the frame in OCM at any moment: what is checked is
	 * exactly what the caller gets, and OCM is never read again. */
	amp__copy_in(h, &f->hdr, sizeof(*h));
	if (h->magic != AMP_FRAME_MAGIC || h->version != AMP_OCM_VERSION ||
	    h->epoch != epoch || h->length > AMP_MBOX_CAPACITY)
		return AMP_E_PROTO;
	if (h->length > cap)
		return AMP_E_NOSPC;
	amp__bytes_in(payload, f->payload, h->length);
	return frame_crc(h, payload) == h->crc32 ? AMP_OK : AMP_E_PROTO;
}

void amp__frame_put(struct amp_frame *f, struct amp_frame_hdr *h,
		    const void *payload)
{
	h->magic = AMP_FRAME_MAGIC;
	h->version = AMP_OCM_VERSION;
	h->crc32 = frame_crc(h, payload);
	amp__bytes_out(f->payload, payload, h->length);
	amp__copy_out(&f->hdr, h, sizeof(*h));
}

int amp__wait_word(const uint32_t *word, uint32_t value, amp_ticks_t timeout)
{
	amp_ticks_t t0 = amp_port_ticks();

	for (;;) {
		AMP_PORT_CACHE_INVAL(word, 4u);
		if (RD_ACQ(word) == value)
			return AMP_OK;
		if ((amp_ticks_t)(amp_port_ticks() - t0) >= timeout)
			return AMP_E_TIMEOUT;
		AMP_PORT_RELAX();
	}
}
