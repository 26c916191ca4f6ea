/* SPDX-License-Identifier: MIT */
/* amp_internal.h - helpers shared by the two sides of amp_lib. */
#ifndef AMP_INTERNAL_H
#define AMP_INTERNAL_H

#include "amp/amp.h"

#define AMP_WD_LIMIT_MAX 1000000u

#define RD(p)    AMP_PORT_LOAD32(p)
#define WR(p, v) AMP_PORT_STORE32((p), (v))
#define MB()     AMP_PORT_MB()
#define RD_ACQ(p)    AMP_PORT_LOAD_ACQ(p)
#define WR_REL(p, v) AMP_PORT_STORE_REL((p), (v))

/* Word-wise copies between local memory and OCM (no memcpy on OCM). */
void amp__copy_in(void *dst, const void *ocm_src, uint32_t bytes);
void amp__copy_out(void *ocm_dst, const void *src, uint32_t bytes);

/*
 * Receive a frame: copy its header into h and its payload into payload (cap
 * bytes available) once each, and validate the copies (magic, version,
 * epoch, length, CRC). AMP_OK, AMP_E_PROTO, or AMP_E_NOSPC (length > cap).
 * The payload is copied a word at a time (one 32-bit load of OCM each),
 * and the CRC computed on each copied word in the same pass.
 */
int amp__frame_recv(struct amp_frame_hdr *h, void *payload, uint32_t cap,
		    const struct amp_frame *f, uint32_t epoch);
/* Write a frame (payload, then header) to OCM; header fields in h, its
 * crc32 computed in the pass that writes the payload. */
void amp__frame_put(struct amp_frame *f, struct amp_frame_hdr *h,
		    const void *payload);

#define AMP_REC_WORDS(type) ((uint32_t)(sizeof(type) / 4u))
#define AMP_REC_END(type)   ((uint32_t)(offsetof(type, seq_end) / 4u))
#define AMP_REC_NAXES(type) ((uint32_t)(offsetof(type, n_axes) / 4u))
#define AMP_REC_W(type, f)  ((uint32_t)(offsetof(type, f) / 4u))

/* Both records: 8 header words (seq_begin first), the axis slots, seq_end. */
#define AMP_REC_HDR_WORDS 8u
_Static_assert(offsetof(struct amp_cmd_record, axis) == 4u * AMP_REC_HDR_WORDS, "cmd header");
_Static_assert(offsetof(struct amp_fb_record, axis) == 4u * AMP_REC_HDR_WORDS, "fb header");

#define FB_WORDS  AMP_REC_WORDS(struct amp_fb_record)
#define FB_END    AMP_REC_END(struct amp_fb_record)
#define FB_NAXES  AMP_REC_NAXES(struct amp_fb_record)
#define FB_SLOT   ((uint32_t)(sizeof(struct amp_fb_axis) / 4u))
#define CMD_WORDS AMP_REC_WORDS(struct amp_cmd_record)
#define CMD_END   AMP_REC_END(struct amp_cmd_record)
#define CMD_NAXES AMP_REC_NAXES(struct amp_cmd_record)
#define CMD_SLOT  ((uint32_t)(sizeof(struct amp_cmd_axis) / 4u))
#define AMP_REC_MAX_END (FB_END > CMD_END ? FB_END : CMD_END)




/* Wait until *word == value, at most timeout ticks. 0 or AMP_E_TIMEOUT. */
int amp__wait_word(const uint32_t *word, uint32_t value, amp_ticks_t timeout);

#include "amp_record.h"

static inline uint32_t amp__ncopy(uint32_t n)
{
	return n > AMP_MAX_AXES ? AMP_MAX_AXES : n;
}

#endif /* AMP_INTERNAL_H */
