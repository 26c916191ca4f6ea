// SPDX-License-Identifier: MIT
/* amp_common.c - CRC, watchdog and record helpers used by both sides. */
#include "amp_internal.h"

#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "amp_lib: the region is little-endian, and the payload copies assume the cores are too"
#endif

/*
 * CRC-32 (IEEE 802.3, reflected, the one zlib computes), a word at a time:
 * a 32-bit little-endian word w of the data is its 4 bytes in order, and
 * the reflected register takes them lowest byte first, so "register ^= w,
 * then 32 bit steps" is the same as 4 bytes of "register ^= byte, then 8
 * bit steps". The register is kept inverted between the steps (the
 * caller's ~ at the start and at the end).
 */
#if AMP_CFG_CRC_SLICE4
#include "amp_crc32_tables.h"

static inline uint32_t crc_word(uint32_t c, uint32_t w)
{
	c ^= w;
	return amp__crc32_t[3][c & 0xffu] ^ amp__crc32_t[2][(c >> 8) & 0xffu] ^
	       amp__crc32_t[1][(c >> 16) & 0xffu] ^ amp__crc32_t[0][c >> 24];
}

static inline uint32_t crc_byte(uint32_t c, uint32_t b)
{
	return (c >> 8) ^ amp__crc32_t[0][(c ^ b) & 0xffu];
}
#else
/* Nibble table: 64 bytes instead of 4 KiB (the firmware's code budget). */
static const uint32_t crc_nib_t[16] = {
	0x00000000u, 0x1db71064u, 0x3b6e20c8u, 0x26d930acu,
	0x76dc4190u, 0x6b6b51f4u, 0x4db26158u, 0x5005713cu,
	0xedb88320u, 0xf00f9344u, 0xd6d6a3e8u, 0xcb61b38cu,
	0x9b64c2b0u, 0x86d3d2d4u, 0xa00ae278u, 0xbdbdf21cu,
};

static inline uint32_t crc_steps(uint32_t c, uint32_t nibbles)
{
	while (nibbles--)
		c = (c >> 4) ^ crc_nib_t[c & 15u];
	return c;
}

static inline uint32_t crc_word(uint32_t c, uint32_t w)
{
	return crc_steps(c ^ w, 8u);
}

static inline uint32_t crc_byte(uint32_t c, uint32_t b)
{
	return crc_steps(c ^ b, 2u);
}
#endif

/* 4 bytes of private memory as a little-endian word, and back (any
 * alignment: the compiler makes one load or store of it) */
static inline uint32_t ld_le(const uint8_t *p)
{
	uint32_t w;

	__builtin_memcpy(&w, p, 4u);
	return w;
}

static inline void st_le(uint8_t *p, uint32_t w)
{
	__builtin_memcpy(p, &w, 4u);
}

uint32_t amp_crc32(uint32_t crc, const void *data, uint32_t len)
{
	const uint8_t *p = data;	/* private memory only: never OCM */

	crc = ~crc;
	for (; len >= 4u; len -= 4u, p += 4)
		crc = crc_word(crc, ld_le(p));
	while (len--)
		crc = crc_byte(crc, *p++);
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

/*
 * Mailbox payloads to and from OCM: one 32-bit access per word of OCM, the
 * bytes in little-endian order (a whole word through the compiler's 4-byte
 * copy, any alignment of the private buffer), the last partial word byte
 * by byte.
 */
static void payload_in(void *dst, const void *ocm_src, uint32_t len)
{
	uint8_t *d = dst;
	const uint32_t *s = ocm_src;
	uint32_t i = 0, w;

	AMP_PORT_CACHE_INVAL(ocm_src, len);
	for (; i + 4u <= len; i += 4u)
		st_le(&d[i], RD(&s[i / 4u]));
	if (i < len)
		for (w = RD(&s[i / 4u]); i < len; i++, w >>= 8)
			d[i] = (uint8_t)w;
}

static void payload_out(void *ocm_dst, const void *src, uint32_t len)
{
	uint32_t *d = ocm_dst;
	const uint8_t *s = src;
	uint32_t i = 0, w = 0;

	for (; i + 4u <= len; i += 4u)
		WR(&d[i / 4u], ld_le(&s[i]));
	if (i < len) {
		for (uint32_t b = 0; i + b < len; b++)
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
	payload_in(payload, f->payload, h->length);
	return frame_crc(h, payload) == h->crc32 ? AMP_OK : AMP_E_PROTO;
}

void amp__frame_put(struct amp_frame *f, struct amp_frame_hdr *h,
		    const void *payload)
{
	h->magic = AMP_FRAME_MAGIC;
	h->version = AMP_OCM_VERSION;
	h->crc32 = frame_crc(h, payload);
	payload_out(f->payload, payload, h->length);
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
