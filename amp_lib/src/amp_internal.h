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

/* Byte payloads to/from OCM with whole-word accesses (little-endian). */
void amp__bytes_in(void *dst, const void *ocm_src, uint32_t len);
void amp__bytes_out(void *ocm_dst, const void *src, uint32_t len);

/*
 * Receive a frame: copy its header into h and its payload into payload (cap
 * bytes available) once each, and validate the copies (magic, version,
 * epoch, length, CRC). AMP_OK, AMP_E_PROTO, or AMP_E_NOSPC (length > cap).
 */
int amp__frame_recv(struct amp_frame_hdr *h, void *payload, uint32_t cap,
		    const struct amp_frame *f, uint32_t epoch);
/* Write a frame (header + payload) to OCM; header fields in h. */
void amp__frame_put(struct amp_frame *f, struct amp_frame_hdr *h,
		    const void *payload);

#define AMP_REC_WORDS(type) ((uint32_t)(sizeof(type) / 4u))
#define AMP_REC_END(type)   ((uint32_t)(offsetof(type, seq_end) / 4u))
#define AMP_REC_NAXES(type) ((uint32_t)(offsetof(type, n_axes) / 4u))

#define FB_WORDS  AMP_REC_WORDS(struct amp_fb_record)
#define FB_END    AMP_REC_END(struct amp_fb_record)
#define FB_NAXES  AMP_REC_NAXES(struct amp_fb_record)
#define CMD_WORDS AMP_REC_WORDS(struct amp_cmd_record)
#define CMD_END   AMP_REC_END(struct amp_cmd_record)
#define CMD_NAXES AMP_REC_NAXES(struct amp_cmd_record)

/*
 * Double-buffered record write/read. words = record size in 32-bit
 * words, end = index of seq_end. The reader returns 0 if the copy in dst
 * is whole and carries sequence seq, -1 if it was torn.
 */
void amp__rec_write(void *ocm_rec, const void *src, uint32_t words,
		    uint32_t end, uint32_t seq);
int amp__rec_read(void *dst, const void *ocm_rec, uint32_t words,
		  uint32_t end, uint32_t seq);

/* Classify a published sequence against the last one read. */
uint32_t amp__rx_classify(uint32_t pub, uint32_t last, uint32_t *missed);

/*
 * The reader's step for a periodic record: classify pub against last,
 * copy the record (buffer pub & 1 of the pair at bufs) into tmp, check it
 * is whole, of this epoch (word 1) and with an axis count (word
 * naxes_word) within AMP_MAX_AXES; fill rx and count the outcome in st.
 * With *resync set (the peer attached anew) the record pub names is
 * checked whatever pub is, last included, and taken as FRESH (missed 0)
 * if whole and valid (an unacceptable record at pub == last is STALE:
 * nothing new yet); *resync is cleared once a record is taken. A copy
 * equal word for word to *held (the record the reader took last; NULL:
 * no such check) is STALE, not taken. Returns 1 if tmp holds a new record
 * the caller must take, else 0.
 */
int amp__rx_record(void *tmp, const void *bufs, uint32_t words, uint32_t end,
		   uint32_t naxes_word, uint32_t pub, uint32_t last, uint32_t epoch,
		   uint32_t *resync, const void *held, struct amp_rx_info *rx,
		   struct amp_stats *st);

/* Wait until *word == value, at most timeout ticks. 0 or AMP_E_TIMEOUT. */
int amp__wait_word(const uint32_t *word, uint32_t value, amp_ticks_t timeout);

static inline uint32_t amp__ncopy(uint32_t n)
{
	return n > AMP_MAX_AXES ? AMP_MAX_AXES : n;
}

#endif /* AMP_INTERNAL_H */
