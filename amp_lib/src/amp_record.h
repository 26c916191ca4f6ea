/* SPDX-License-Identifier: MIT */
/*
 * amp_record.h - the periodic records' seqlock, writer and reader, shared
 * by the two sides of amp_lib. Static inline, so that each side's cycle
 * compiles them with its own record's constants (sizes, word indexes, the
 * "same record" check only on the Linux side) folded in: no call with a
 * dozen arguments, no loop bound read at run time (issue 24).
 * Included by amp_internal.h only.
 */
#ifndef AMP_RECORD_H
#define AMP_RECORD_H

/*
 * The word loops below go four words at a time when built for speed (the
 * firmware's -O2: about 2.5 instructions a word instead of 4 on the
 * Cortex-A9), one at a time when built for size (-Os: the footprint
 * budget of bench/amp_footprint.py).
 */
#if defined(__OPTIMIZE_SIZE__)
#define AMP__BY4 0
#else
#define AMP__BY4 1
#endif

/* n words from private memory to OCM and back (no memcpy on OCM: one
 * 32-bit access per word, in order) */
static inline void amp__ocm_put(uint32_t *d, const uint32_t *s, uint32_t n)
{
	const uint32_t *e = s + n;

	for (; AMP__BY4 && e - s >= 4; s += 4, d += 4) {
		WR(&d[0], s[0]);
		WR(&d[1], s[1]);
		WR(&d[2], s[2]);
		WR(&d[3], s[3]);
	}
	for (; s < e; s++, d++)
		WR(d, *s);
}

static inline void amp__ocm_get(uint32_t *d, const uint32_t *s, uint32_t n)
{
	const uint32_t *e = s + n;

	for (; AMP__BY4 && e - s >= 4; s += 4, d += 4) {
		d[0] = RD(&s[0]);
		d[1] = RD(&s[1]);
		d[2] = RD(&s[2]);
		d[3] = RD(&s[3]);
	}
	for (; s < e; s++, d++)
		*d = RD(s);
}

/*
 * The seqlock of the periodic records (docs/amp-protocol.md, section 8):
 *   writer: seq_begin = s; WMB (1); payload; WMB (2); seq_end = s;
 *           then the caller publishes s with a release store (3)
 *   reader: pub with an acquire load (3'); seq_end; RMB (2'); payload;
 *           RMB (1'); seq_begin
 * (2) pairs with (2'): a reader that saw seq_end = s sees the payload of
 * s (or of a later write). (1) pairs with (1'): a reader that saw any word
 * of a later write of the same buffer (s + 2) sees its seq_begin, so the
 * copy is refused as torn. (3)/(3') order the record before the sequence
 * that names it.
 */
/*
 * Double-buffered record write/read (the seqlock: amp_common.c says which
 * barrier pairs with which). The writer writes seq_begin = seq, header
 * words 1..7 from hdr, axis_words words of axis slots from axes (the
 * caller's n_axes slots; the slots past them are not written), then
 * seq_end = seq (word end). The reader copies seq_end, header words 1..7,
 * the slots of the copy's own n_axes (word naxes_word; none if it is over
 * AMP_MAX_AXES), seq_begin, into d; *axis_words is the number of slot
 * words copied. It returns 0 if the copy is whole and carries sequence
 * seq, -1 if it was torn.
 */
static inline void amp__rec_write(void *ocm_rec, const uint32_t *hdr, const void *axes,
		    uint32_t axis_words, uint32_t end, uint32_t seq)
{
	uint32_t *d = ocm_rec;

	WR(&d[0], seq);
	AMP_PORT_CACHE_CLEAN(d, 4u);
	AMP_PORT_WMB();				/* (1) */
	amp__ocm_put(&d[1], &hdr[1], AMP_REC_HDR_WORDS - 1u);
	amp__ocm_put(&d[AMP_REC_HDR_WORDS], axes, axis_words);
	AMP_PORT_CACHE_CLEAN(d, (AMP_REC_HDR_WORDS + axis_words) * 4u);
	AMP_PORT_WMB();				/* (2) */
	WR(&d[end], seq);
	AMP_PORT_CACHE_CLEAN(&d[end], 4u);
	/* (3): the caller publishes seq with a release store */
}

static inline int amp__rec_read(uint32_t *d, const void *ocm_rec, uint32_t naxes_word,
		  uint32_t slot_words, uint32_t end, uint32_t seq, uint32_t *axis_words)
{
	const uint32_t *s = ocm_rec;
	uint32_t e, b, n;

	AMP_PORT_CACHE_INVAL(s, (end + 1u) * 4u);
	e = RD(&s[end]);
	AMP_PORT_RMB();				/* (2') */
	amp__ocm_get(&d[1], &s[1], AMP_REC_HDR_WORDS - 1u);
	/* the slots the copy's own axis count names (none if over the
	 * maximum: such a record is refused anyway) */
	n = d[naxes_word];
	n = n > AMP_MAX_AXES ? 0u : n * slot_words;
	amp__ocm_get(&d[AMP_REC_HDR_WORDS], &s[AMP_REC_HDR_WORDS], n);
	AMP_PORT_RMB();				/* (1') */
	AMP_PORT_CACHE_INVAL(s, 4u);
	b = RD(&s[0]);
	d[0] = b;
	d[end] = e;
	*axis_words = n;
	return (b == e && e == seq) ? 0 : -1;
}

/* Classify a published sequence against the last one read. */
static inline uint32_t amp__rx_classify(uint32_t pub, uint32_t last, uint32_t *missed)
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

/* n words of private memory: the C library's memcpy in a hosted build,
 * a word loop in the firmware (whose memcpy goes a byte at a time) */
static inline void amp__words_copy(uint32_t *d, const uint32_t *s, uint32_t n)
{
#if __STDC_HOSTED__
	__builtin_memcpy(d, s, n * 4u);
#else
	const uint32_t *e = s + n;

	for (; AMP__BY4 && e - s >= 4; s += 4, d += 4) {
		d[0] = s[0];
		d[1] = s[1];
		d[2] = s[2];
		d[3] = s[3];
	}
	for (; s < e; s++, d++)
		*d = *s;
#endif
}

/* the copy t (its header, axis_words words of slots, seq_end) is word for
 * word the record held: equal headers mean equal axis counts, and the held
 * record's slots past its count are 0 (amp__rx_record) */
static inline int amp__same_record(const uint32_t *t, const uint32_t *held, uint32_t used, uint32_t end)
{
	for (uint32_t i = 0; i < used; i++)
		if (t[i] != held[i])
			return 0;
	return t[end] == held[end];
}

/*
 * The reader's step for a periodic record: classify pub against last,
 * copy the record (buffer pub & 1 of the pair at bufs, words words each)
 * into a private copy, check it is whole, of this epoch (word 1) and with
 * an axis count (word naxes_word) within AMP_MAX_AXES; fill rx and count
 * the outcome in st. With *resync set (the peer attached anew) the record
 * pub names is checked whatever pub is, last included, and taken as FRESH
 * (missed 0) if whole and valid (an unacceptable record at pub == last is
 * STALE: nothing new yet); *resync is cleared once a record is taken.
 * With check_same, a copy equal word for word to *held (the record the
 * reader took last) is STALE, not taken. Returns 1 if the copy was taken:
 * *held is then the new record (its header, its n_axes slots of
 * slot_words words, 0 in the slots past them, seq_end), else 0 and *held
 * is unchanged.
 */
static inline int amp__rx_record(void *held, int check_same, const void *bufs, uint32_t words,
		   uint32_t end, uint32_t naxes_word, uint32_t slot_words, uint32_t pub,
		   uint32_t last, uint32_t epoch, uint32_t *resync, struct amp_rx_info *rx,
		   struct amp_stats *st)
{
	const uint32_t *rec = (const uint32_t *)bufs + (pub & 1u) * words;
	uint32_t t[AMP_REC_MAX_END + 1u];	/* the copy, checked before it is taken */
	uint32_t *h = held;
	uint32_t aw = 0, used;
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
		if (amp__rec_read(t, rec, naxes_word, slot_words, end, pub, &aw) != 0)
			rx->status = AMP_RX_TORN;
		else if (t[1] != epoch || t[naxes_word] > AMP_MAX_AXES)
			rx->status = AMP_RX_INVALID;
		else if (check_same && amp__same_record(t, h, AMP_REC_HDR_WORDS + aw, end))
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
	if (take) {
		/* the copy becomes the record held: its header, the slots of
		 * its axes, 0 in the slots past them (the writer does not write
		 * those), its seq_end; nothing read from OCM again */
		used = AMP_REC_HDR_WORDS + aw;
		amp__words_copy(h, t, used);
		for (uint32_t i = used; i < end; i++)
			h[i] = 0;
		h[end] = t[end];
		*resync = 0;
	}
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

#endif /* AMP_RECORD_H */
