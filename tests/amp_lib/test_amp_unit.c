// SPDX-License-Identifier: MIT
/*
 * Unit tests of amp_lib on the host: both sides in one thread over a
 * local buffer standing in for OCM, every function and error path.
 */
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "amp/amp.h"
#include "check.h"

static _Alignas(64) uint8_t ocm_buf[AMP_OCM_SIZE + 64];
#define OCM ((struct amp_ocm *)ocm_buf)

static struct amp_linux L;
static struct amp_servo S;

static void fresh_pair(uint32_t wd)
{
	memset(ocm_buf, 0, sizeof(ocm_buf));
	CHECK_EQ(amp_linux_init(&L, ocm_buf, sizeof(ocm_buf), wd), AMP_OK);
	CHECK_EQ(amp_servo_attach(&S, ocm_buf, sizeof(ocm_buf)), AMP_OK);
}

static void fill_cmd(struct amp_cmd_axis *a, uint32_t n, int32_t base)
{
	for (uint32_t i = 0; i < n; i++) {
		a[i].control_word = AMP_AXIS_ENABLE;
		a[i].target_pos = base + (int32_t)i * 1000;
		a[i].vel_ff = base * 2 + (int32_t)i;
		a[i].torque_offset = -(int32_t)i;
	}
}

static void test_crc(void)
{
	CHECK_EQ(amp_crc32(0, "123456789", 9), 0xcbf43926u);
	CHECK_EQ(amp_crc32(0, "", 0), 0);
	/* continuation equals one pass */
	CHECK_EQ(amp_crc32(amp_crc32(0, "1234", 4), "56789", 5), 0xcbf43926u);

	/* a word at a time (either table: AMP_CFG_CRC_SLICE4) equals the
	 * bit-at-a-time definition, at every alignment and for every length
	 * up to 64 bytes, split anywhere */
	{
		static uint8_t buf[64 + 3];
		uint32_t x = 2463534242u;

		for (uint32_t i = 0; i < sizeof(buf); i++) {
			x ^= x << 13;
			x ^= x >> 17;
			x ^= x << 5;
			buf[i] = (uint8_t)x;
		}
		for (uint32_t off = 0; off < 4u; off++)
			for (uint32_t len = 0; len <= 64u; len++) {
				uint32_t ref = 0xffffffffu, split = len / 3u;

				for (uint32_t i = 0; i < len; i++) {
					ref ^= buf[off + i];
					for (int b = 0; b < 8; b++)
						ref = (ref >> 1) ^ (0xedb88320u & (0u - (ref & 1u)));
				}
				ref = ~ref;
				CHECK_EQ(amp_crc32(0, buf + off, len), ref);
				CHECK_EQ(amp_crc32(amp_crc32(0, buf + off, split), buf + off + split,
						   len - split), ref);
			}
	}
}

static void test_strerror(void)
{
	int codes[] = { AMP_OK, AMP_E_PEER_ABSENT, AMP_E_PEER_ERROR, AMP_E_TIMEOUT,
			AMP_E_PROTO, AMP_E_INVAL, AMP_E_LAYOUT, AMP_E_BUSY,
			AMP_E_NOSPC, AMP_E_STALLED, AMP_E_FEEDBACK, AMP_E_PEER_STOPPING };
	size_t n = sizeof(codes) / sizeof(codes[0]);

	for (size_t i = 0; i < n; i++) {
		CHECK(strcmp(amp_strerror(codes[i]), "unknown error") != 0);
		for (size_t j = i + 1; j < n; j++)
			CHECK(strcmp(amp_strerror(codes[i]), amp_strerror(codes[j])) != 0);
	}
	CHECK(strcmp(amp_strerror(-1000), "unknown error") == 0);
}

static void test_watchdog(void)
{
	struct amp_watchdog wd = { .limit = 3 };

	CHECK_EQ(amp_wd_feed(&wd, 5), AMP_OK);
	CHECK_EQ(amp_wd_feed(&wd, 5), AMP_OK);	/* still 1 */
	CHECK_EQ(amp_wd_feed(&wd, 5), AMP_OK);	/* still 2 */
	CHECK_EQ(amp_wd_feed(&wd, 5), AMP_E_STALLED);	/* still 3 = limit */
	CHECK_EQ(amp_wd_feed(&wd, 5), AMP_E_STALLED);
	CHECK_EQ(amp_wd_feed(&wd, 6), AMP_OK);	/* moving again */
	CHECK_EQ(amp_wd_feed(&wd, 7), AMP_OK);
}

static void test_init_args(void)
{
	struct amp_linux l;

	CHECK_EQ(amp_linux_init(NULL, ocm_buf, sizeof(ocm_buf), 0), AMP_E_INVAL);
	CHECK_EQ(amp_linux_init(&l, NULL, sizeof(ocm_buf), 0), AMP_E_INVAL);
	CHECK_EQ(amp_linux_init(&l, ocm_buf + 4, sizeof(ocm_buf) - 4, 0), AMP_E_INVAL);
	CHECK_EQ(amp_linux_init(&l, ocm_buf, AMP_OCM_SIZE - 1, 0), AMP_E_INVAL);
	CHECK_EQ(amp_linux_init(&l, ocm_buf, sizeof(ocm_buf), 1000001), AMP_E_INVAL);
	CHECK_EQ(amp_linux_init(&l, ocm_buf, AMP_OCM_SIZE, 0), AMP_OK);
	CHECK_EQ(OCM->hdr.wd_limit, AMP_WD_LIMIT_DEFAULT);
	CHECK_EQ(OCM->hdr.total_size, AMP_OCM_SIZE);
	CHECK_EQ(OCM->cyc_sem.sem, AMP_SEM_IDLE);
	CHECK_EQ(OCM->mbox_sem.sem, AMP_SEM_IDLE);
	CHECK_EQ(OCM->linux_line.state, AMP_LSTATE_READY);
}

static void test_attach_checks(void)
{
	struct amp_servo s;
	uint32_t crc;

	memset(ocm_buf, 0, sizeof(ocm_buf));
	CHECK_EQ(amp_servo_attach(&s, ocm_buf, sizeof(ocm_buf)), AMP_E_PEER_ABSENT);
	CHECK_EQ(amp_servo_attach(NULL, ocm_buf, sizeof(ocm_buf)), AMP_E_INVAL);
	CHECK_EQ(amp_servo_attach(&s, ocm_buf + 8, sizeof(ocm_buf) - 8), AMP_E_INVAL);
	CHECK_EQ(amp_linux_init(&L, ocm_buf, sizeof(ocm_buf), 0), AMP_OK);
	CHECK_EQ(amp_servo_attach(&s, ocm_buf, 64), AMP_E_INVAL);

	/* each header field wrong in turn -> layout mismatch */
	OCM->hdr.version = 2;
	CHECK_EQ(amp_servo_attach(&s, ocm_buf, sizeof(ocm_buf)), AMP_E_LAYOUT);
	OCM->hdr.version = AMP_OCM_VERSION;
	CHECK_EQ(amp_servo_attach(&s, ocm_buf, sizeof(ocm_buf)), AMP_OK);
	OCM->hdr.max_axes = AMP_MAX_AXES + 1;
	CHECK_EQ(amp_servo_attach(&s, ocm_buf, sizeof(ocm_buf)), AMP_E_LAYOUT);
	OCM->hdr.max_axes = AMP_MAX_AXES;
	OCM->hdr.total_size += 32;
	CHECK_EQ(amp_servo_attach(&s, ocm_buf, sizeof(ocm_buf)), AMP_E_LAYOUT);
	OCM->hdr.total_size -= 32;
	OCM->hdr.mbox_capacity = 64;
	CHECK_EQ(amp_servo_attach(&s, ocm_buf, sizeof(ocm_buf)), AMP_E_LAYOUT);
	OCM->hdr.mbox_capacity = AMP_MBOX_CAPACITY;
	crc = OCM->hdr.crc32;
	OCM->hdr.crc32 ^= 1;
	CHECK_EQ(amp_servo_attach(&s, ocm_buf, sizeof(ocm_buf)), AMP_E_LAYOUT);
	OCM->hdr.crc32 = crc;
	OCM->hdr.wd_limit = 0;	/* and a CRC that matches the bad value */
	OCM->hdr.crc32 = amp_crc32(0, &OCM->hdr, 28);
	CHECK_EQ(amp_servo_attach(&s, ocm_buf, sizeof(ocm_buf)), AMP_E_LAYOUT);

	/* region being (re)written by Linux: not a live peer yet */
	CHECK_EQ(amp_linux_init(&L, ocm_buf, sizeof(ocm_buf), 0), AMP_OK);
	OCM->linux_line.state = AMP_LSTATE_INIT;
	CHECK_EQ(amp_servo_attach(&s, ocm_buf, sizeof(ocm_buf)), AMP_E_PEER_ABSENT);
	OCM->linux_line.state = AMP_LSTATE_READY;
	CHECK_EQ(amp_servo_attach(&s, ocm_buf, sizeof(ocm_buf)), AMP_OK);
}

static void test_peer_and_epoch(void)
{
	struct amp_rx_info rx;
	uint32_t old_epoch;
	struct amp_cmd_axis a[2];

	memset(ocm_buf, 0, sizeof(ocm_buf));
	CHECK_EQ(amp_linux_init(&L, ocm_buf, sizeof(ocm_buf), 0), AMP_OK);
	CHECK_EQ(amp_linux_peer(&L), AMP_E_PEER_ABSENT);
	fill_cmd(a, 2, 1);
	CHECK_EQ(amp_linux_cycle(&L, a, 2, 0, &rx), AMP_E_PEER_ABSENT);
	CHECK_EQ(amp_servo_attach(&S, ocm_buf, sizeof(ocm_buf)), AMP_OK);
	CHECK_EQ(amp_linux_peer(&L), AMP_OK);
	CHECK_EQ(OCM->servo_line.attach_count, 1);

	/* a servo fault is reported as a peer error */
	amp_servo_set_state(&S, AMP_SSTATE_FAULT, 77);
	CHECK_EQ(amp_linux_peer(&L), AMP_E_PEER_ERROR);
	CHECK_EQ(amp_linux_cycle(&L, a, 2, 0, &rx), AMP_E_PEER_ERROR);
	CHECK_EQ(OCM->servo_line.fault, 77);
	amp_servo_set_state(&S, AMP_SSTATE_SAFESTOP, 0);
	CHECK_EQ(amp_linux_peer(&L), AMP_OK);

	/* re-initialising gives a new epoch: the old servo attachment (stale
	 * contents) is not a live peer, and the servo sees Linux went away */
	old_epoch = L.epoch;
	CHECK_EQ(amp_linux_init(&L, ocm_buf, sizeof(ocm_buf), 0), AMP_OK);
	CHECK(L.epoch != old_epoch);
	CHECK(L.epoch != 0);
	CHECK_EQ(amp_linux_peer(&L), AMP_E_PEER_ABSENT);
	CHECK_EQ(amp_servo_cycle_rx(&S, 0, &rx), AMP_E_PEER_ABSENT);

	/* stale contents: a snapshot of a live session restored over a newly
	 * initialised region's servo line must not count as attached: another
	 * epoch with an attach count (which init zeroed) is a peer error (the
	 * line was written over), recovered like one, never AMP_OK */
	CHECK_EQ(amp_servo_attach(&S, ocm_buf, sizeof(ocm_buf)), AMP_OK);
	{
		struct amp_servo_line snap;
		memcpy(&snap, &OCM->servo_line, sizeof(snap));
		CHECK_EQ(amp_linux_init(&L, ocm_buf, sizeof(ocm_buf), 0), AMP_OK);
		memcpy(&OCM->servo_line, &snap, sizeof(snap));
		CHECK_EQ(amp_linux_peer(&L), AMP_E_PEER_ERROR);
		/* the same epoch word without an attach count: an earlier
		 * session's servo, not attached to this one */
		OCM->servo_line.attach_count = 0;
		CHECK_EQ(amp_linux_peer(&L), AMP_E_PEER_ABSENT);
	}

	/* epoch wraps past zero without becoming zero */
	OCM->hdr.epoch = 0xffffffffu;
	CHECK_EQ(amp_linux_init(&L, ocm_buf, sizeof(ocm_buf), 0), AMP_OK);
	CHECK_EQ(L.epoch, 1);

	/* Linux closes the link: the servo notices */
	CHECK_EQ(amp_servo_attach(&S, ocm_buf, sizeof(ocm_buf)), AMP_OK);
	amp_linux_close(&L);
	CHECK_EQ(amp_servo_cycle_rx(&S, 0, &rx), AMP_E_PEER_ABSENT);
	CHECK_EQ(amp_servo_attach(&S, ocm_buf, sizeof(ocm_buf)), AMP_E_PEER_ABSENT);
}

static void test_periodic(void)
{
	struct amp_cmd_axis a[AMP_MAX_AXES];
	struct amp_fb_axis f[AMP_MAX_AXES];
	struct amp_rx_info rx;

	fresh_pair(5);
	memset(f, 0, sizeof(f));

	/* bad arguments */
	CHECK_EQ(amp_linux_cycle(&L, a, AMP_MAX_AXES + 1, 0, &rx), AMP_E_INVAL);
	CHECK_EQ(amp_linux_cycle(&L, NULL, 1, 0, &rx), AMP_E_INVAL);
	CHECK_EQ(amp_servo_cycle_tx(&S, f, AMP_MAX_AXES + 1, 0, 0), AMP_E_INVAL);
	CHECK_EQ(amp_servo_cycle_tx(&S, NULL, 2, 0, 0), AMP_E_INVAL);

	/* nothing posted yet: stale */
	CHECK_EQ(amp_servo_cycle_rx(&S, 0, &rx), AMP_OK);
	CHECK_EQ(rx.status, AMP_RX_STALE);

	/* Linux posts: semaphore busy, servo reads fresh data */
	fill_cmd(a, 3, 100);
	CHECK_EQ(amp_linux_cycle(&L, a, 3, 0x5, &rx), AMP_OK);
	CHECK_EQ(rx.status, AMP_RX_STALE);	/* no feedback yet */
	CHECK_EQ(OCM->cyc_sem.sem, AMP_SEM_BUSY);
	CHECK_EQ(amp_servo_cycle_rx(&S, 0, &rx), AMP_OK);
	CHECK_EQ(rx.status, AMP_RX_FRESH);
	CHECK_EQ(rx.seq, 1);
	CHECK_EQ(S.cmd.n_axes, 3);
	CHECK_EQ(S.cmd.flags, 0x5);
	CHECK_EQ(S.cmd.axis[2].target_pos, 2100);
	CHECK_EQ(S.cmd.axis[1].vel_ff, 201);

	/* servo answers: semaphore idle, Linux reads fresh feedback */
	f[0].actual_pos = 42;
	f[1].following_error = -7;
	CHECK_EQ(amp_servo_cycle_tx(&S, f, 2, 1234, 56), AMP_OK);
	CHECK_EQ(OCM->cyc_sem.sem, AMP_SEM_IDLE);
	CHECK_EQ(amp_linux_cycle(&L, a, 3, 0, &rx), AMP_OK);
	CHECK_EQ(rx.status, AMP_RX_FRESH);
	CHECK_EQ(rx.seq, 1);
	CHECK_EQ(L.fb.axis[0].actual_pos, 42);
	CHECK_EQ(L.fb.axis[1].following_error, -7);
	CHECK_EQ(L.fb.t_cycle, 1234);
	CHECK_EQ(L.fb.irq_latency, 56);
	CHECK_EQ(L.fb.cmd_seq, 1);
	CHECK_EQ(L.fb.n_axes, 2);
	CHECK_EQ(L.fb.status, AMP_SSTATE_RUNNING);
	CHECK_EQ(L.st.peer_late, 0);

	/* servo consumes seq 2; then two cycles where Linux gets nothing new */
	CHECK_EQ(amp_servo_cycle_rx(&S, 0, &rx), AMP_OK);
	CHECK_EQ(rx.status, AMP_RX_FRESH);
	CHECK_EQ(amp_linux_cycle(&L, a, 3, 0, &rx), AMP_OK);
	CHECK_EQ(rx.status, AMP_RX_STALE);
	CHECK_EQ(L.st.peer_late, 1);	/* semaphore was still busy */

	/* Linux posts seq 3 and 4 (the second while busy); servo misses 3 */
	fill_cmd(a, 3, 500);
	CHECK_EQ(amp_linux_cycle(&L, a, 3, 0, &rx), AMP_OK);
	CHECK_EQ(amp_servo_cycle_rx(&S, 0, &rx), AMP_OK);
	CHECK_EQ(rx.status, AMP_RX_MISSED);
	CHECK_EQ(rx.missed, 1);
	CHECK_EQ(rx.seq, 4);
	CHECK_EQ(S.cmd.axis[0].target_pos, 500);
	CHECK_EQ(S.st.missed, 1);
	CHECK_EQ(OCM->servo_line.cmd_missed, 1);

	/* servo publishes twice without Linux reading: Linux sees one missed */
	CHECK_EQ(amp_servo_cycle_tx(&S, f, 2, 0, 0), AMP_OK);
	CHECK_EQ(amp_servo_cycle_tx(&S, f, 2, 0, 0), AMP_OK);
	CHECK_EQ(amp_linux_cycle(&L, a, 3, 0, &rx), AMP_OK);
	CHECK_EQ(rx.status, AMP_RX_MISSED);
	CHECK_EQ(rx.missed, 1);

	/* torn: the buffer's seq_begin no longer matches (writer lapped us);
	 * the previous commands are kept */
	CHECK_EQ(amp_servo_cycle_rx(&S, 0, &rx), AMP_OK);
	CHECK_EQ(rx.status, AMP_RX_FRESH);
	fill_cmd(a, 3, 900);
	CHECK_EQ(amp_linux_cycle(&L, a, 3, 0, &rx), AMP_OK);
	OCM->cmd[L.cmd_seq & 1].seq_begin = L.cmd_seq + 2;
	CHECK_EQ(amp_servo_cycle_rx(&S, 0, &rx), AMP_OK);
	CHECK_EQ(rx.status, AMP_RX_TORN);
	CHECK_EQ(S.cmd.axis[0].target_pos, 500);
	CHECK_EQ(S.st.torn, 1);
	/* the seq_end side too */
	OCM->cmd[L.cmd_seq & 1].seq_begin = L.cmd_seq;
	OCM->cmd[L.cmd_seq & 1].seq_end = L.cmd_seq - 2;
	CHECK_EQ(amp_servo_cycle_rx(&S, 0, &rx), AMP_OK);
	CHECK_EQ(rx.status, AMP_RX_TORN);
	OCM->cmd[L.cmd_seq & 1].seq_end = L.cmd_seq;
	CHECK_EQ(amp_servo_cycle_rx(&S, 0, &rx), AMP_OK);
	CHECK_EQ(rx.status, AMP_RX_FRESH);
	CHECK_EQ(S.cmd.axis[0].target_pos, 900);

	/* an axis count beyond the configured maximum is refused */
	CHECK_EQ(amp_linux_cycle(&L, a, 3, 0, &rx), AMP_OK);
	OCM->cmd[L.cmd_seq & 1].n_axes = AMP_MAX_AXES + 1;
	CHECK_EQ(amp_servo_cycle_rx(&S, 0, &rx), AMP_OK);
	CHECK_EQ(rx.status, AMP_RX_INVALID);
	CHECK_EQ(S.cmd.n_axes, 3);
	/* a record from another epoch is refused */
	CHECK_EQ(amp_linux_cycle(&L, a, 3, 0, &rx), AMP_OK);
	OCM->cmd[L.cmd_seq & 1].epoch ^= 0x100;
	CHECK_EQ(amp_servo_cycle_rx(&S, 0, &rx), AMP_OK);
	CHECK_EQ(rx.status, AMP_RX_INVALID);
	/* a sequence that goes backwards (reordered/duplicated) is refused */
	S.cmd_seq = L.cmd_seq + 5;
	CHECK_EQ(amp_servo_cycle_rx(&S, 0, &rx), AMP_OK);
	CHECK_EQ(rx.status, AMP_RX_INVALID);
	S.cmd_seq = L.cmd_seq - 1;
	CHECK_EQ(amp_servo_cycle_rx(&S, 0, &rx), AMP_OK);	/* recovers */

	/* feedback validation on the Linux side */
	CHECK_EQ(amp_servo_cycle_tx(&S, f, 2, 0, 0), AMP_OK);
	OCM->fb[S.fb_seq & 1].n_axes = 99;
	CHECK_EQ(amp_linux_cycle(&L, a, 3, 0, &rx), AMP_OK);
	CHECK_EQ(rx.status, AMP_RX_INVALID);
	CHECK_EQ(amp_servo_cycle_tx(&S, f, 2, 0, 0), AMP_OK);
	OCM->fb[S.fb_seq & 1].seq_begin++;
	CHECK_EQ(amp_linux_cycle(&L, a, 3, 0, &rx), AMP_OK);
	CHECK_EQ(rx.status, AMP_RX_TORN);
	CHECK(L.st.torn >= 1);
	CHECK(L.st.invalid >= 1);

	/* the wait for the semaphore is bounded by the timeout */
	{
		uint32_t t0 = amp_port_ticks();
		CHECK_EQ(amp_servo_cycle_rx(&S, 0, &rx), AMP_OK);	/* consume */
		CHECK_EQ(amp_servo_cycle_tx(&S, f, 2, 0, 0), AMP_OK);	/* release */
		t0 = amp_port_ticks();
		CHECK_EQ(amp_servo_cycle_rx(&S, 20000, &rx), AMP_OK);
		CHECK_EQ(rx.status, AMP_RX_STALE);
		CHECK((uint32_t)(amp_port_ticks() - t0) >= 20000);
	}
}

static void test_watchdogs_both_ways(void)
{
	struct amp_cmd_axis a[1];
	struct amp_fb_axis f[1];
	struct amp_rx_info rx;
	int rc = AMP_OK, n;

	fresh_pair(4);
	fill_cmd(a, 1, 0);
	memset(f, 0, sizeof(f));
	/* healthy: both advance, no detection over many cycles */
	for (n = 0; n < 100; n++) {
		CHECK_EQ(amp_linux_cycle(&L, a, 1, 0, &rx), AMP_OK);
		CHECK_EQ(amp_servo_cycle_rx(&S, 0, &rx), AMP_OK);
		CHECK_EQ(amp_servo_cycle_tx(&S, f, 1, 0, 0), AMP_OK);
	}
	/* servo stalls: the first Linux cycle still sees its last beat, the
	 * limit-th cycle without a beat (here 4) detects it, not earlier */
	for (n = 1; n <= 10 && (rc = amp_linux_cycle(&L, a, 1, 0, &rx)) == AMP_OK; n++)
		;
	CHECK_EQ(rc, AMP_E_STALLED);
	CHECK_EQ(n, 1 + 4);
	/* servo resumes: its heartbeat goes out with the feedback */
	CHECK_EQ(amp_servo_cycle_rx(&S, 0, &rx), AMP_OK);
	CHECK_EQ(amp_servo_cycle_tx(&S, f, 1, 0, 0), AMP_OK);
	CHECK_EQ(amp_linux_cycle(&L, a, 1, 0, &rx), AMP_OK);
	/* a cycle without exchange still beats through amp_servo_heartbeat */
	amp_servo_heartbeat(&S);
	CHECK_EQ(amp_linux_cycle(&L, a, 1, 0, &rx), AMP_OK);
	/* Linux stalls: the servo detects it at exactly the limit */
	for (n = 1; n <= 10 && (rc = amp_servo_cycle_rx(&S, 0, &rx)) == AMP_OK; n++)
		;
	CHECK_EQ(rc, AMP_E_STALLED);
	CHECK_EQ(n, 1 + 4);
	CHECK_EQ(amp_linux_cycle(&L, a, 1, 0, &rx), AMP_OK);
	CHECK_EQ(amp_servo_cycle_rx(&S, 0, &rx), AMP_OK);
	CHECK_EQ(amp_servo_cycle_tx(&S, f, 1, 0, 0), AMP_OK);
	CHECK_EQ(amp_linux_cycle(&L, a, 1, 0, &rx), AMP_OK);

	/* the servo restarts in the same epoch: sequences continue, the
	 * restart is counted, Linux re-primes its watchdog */
	{
		uint32_t fb = S.fb_seq;
		CHECK_EQ(amp_servo_attach(&S, ocm_buf, sizeof(ocm_buf)), AMP_OK);
		CHECK_EQ(OCM->servo_line.attach_count, 2);
		CHECK_EQ(S.fb_seq, fb);
		CHECK_EQ(amp_servo_cycle_tx(&S, f, 1, 0, 0), AMP_OK);
		CHECK_EQ(amp_linux_cycle(&L, a, 1, 0, &rx), AMP_OK);
		CHECK_EQ(rx.status, AMP_RX_FRESH);
	}
}

static uint8_t big[AMP_MBOX_CAPACITY + 8];

static void test_mailbox(void)
{
	struct amp_msg req = { 0 }, resp = { 0 };
	struct amp_mbox_req sr;
	uint8_t out[AMP_MBOX_CAPACITY], in[AMP_MBOX_CAPACITY];
	uint32_t n;

	fresh_pair(0);
	for (n = 0; n < sizeof(out); n++)
		out[n] = (uint8_t)(n * 7 + 3);

	/* nothing pending: poll says so */
	CHECK_EQ(amp_servo_mbox_poll(&S, &sr), 0);
	CHECK_EQ(amp_linux_mbox_poll(&L, &resp), AMP_E_INVAL);
	CHECK_EQ(amp_servo_mbox_respond(&S, 0, NULL, 0), AMP_E_INVAL);

	/* argument checks */
	req.command = 9;
	req.length = AMP_MBOX_CAPACITY + 1;
	req.data = big;
	CHECK_EQ(amp_linux_mbox_post(&L, &req), AMP_E_NOSPC);
	req.length = 4;
	req.data = NULL;
	CHECK_EQ(amp_linux_mbox_post(&L, &req), AMP_E_INVAL);

	/* every length from 0 to capacity, odd ones included, round trips */
	for (n = 0; n <= AMP_MBOX_CAPACITY; n += (n < 40 ? 1 : 61)) {
		req.command = 0x100 + n;
		req.length = n;
		req.data = out;
		CHECK_EQ(amp_linux_mbox_post(&L, &req), AMP_OK);
		CHECK_EQ(OCM->mbox_sem.sem, AMP_SEM_BUSY);
		CHECK_EQ(amp_linux_mbox_post(&L, &req), AMP_E_BUSY);
		resp.data = in;
		resp.capacity = sizeof(in);
		CHECK_EQ(amp_linux_mbox_poll(&L, &resp), AMP_E_BUSY);
		CHECK_EQ(amp_servo_mbox_poll(&S, &sr), 1);
		CHECK_EQ(amp_servo_mbox_poll(&S, &sr), 0);	/* handed out once */
		CHECK_EQ(sr.command, 0x100 + n);
		CHECK_EQ(sr.length, n);
		{
			uint8_t echo[AMP_MBOX_CAPACITY];
			for (uint32_t i = 0; i < sr.length; i++)
				echo[i] = (uint8_t)(255u - sr.payload[i]);
			CHECK_EQ(amp_servo_mbox_respond(&S, 7, echo, sr.length), AMP_OK);
		}
		CHECK_EQ(OCM->mbox_sem.sem, AMP_SEM_IDLE);
		memset(in, 0, sizeof(in));
		CHECK_EQ(amp_linux_mbox_poll(&L, &resp), AMP_OK);
		CHECK_EQ(resp.status, 7);
		CHECK_EQ(resp.length, n);
		CHECK_EQ(resp.command, 0x100 + n);
		{
			int same = 1;
			for (uint32_t i = 0; i < n; i++) {
				uint8_t want = (uint8_t)(255u - out[i]);

				same &= in[i] == want;
			}
			CHECK(same);
		}
	}

	/* the servo cannot answer with more than the capacity */
	req.length = 4;
	CHECK_EQ(amp_linux_mbox_post(&L, &req), AMP_OK);
	CHECK_EQ(amp_servo_mbox_poll(&S, &sr), 1);
	CHECK_EQ(amp_servo_mbox_respond(&S, 0, big, AMP_MBOX_CAPACITY + 1), AMP_E_NOSPC);
	/* a response larger than the caller's buffer is refused */
	CHECK_EQ(amp_servo_mbox_respond(&S, 0, out, 64), AMP_OK);
	resp.capacity = 16;
	CHECK_EQ(amp_linux_mbox_poll(&L, &resp), AMP_E_NOSPC);
	resp.capacity = sizeof(in);

	/* a corrupted request: the servo refuses it and says so */
	req.length = 32;
	CHECK_EQ(amp_linux_mbox_post(&L, &req), AMP_OK);
	OCM->req.payload[5] ^= 0x20;
	CHECK_EQ(amp_servo_mbox_poll(&S, &sr), AMP_E_PROTO);
	CHECK_EQ(amp_linux_mbox_poll(&L, &resp), AMP_OK);
	CHECK_EQ(resp.status, AMP_E_PROTO);
	/* a request length beyond the capacity */
	CHECK_EQ(amp_linux_mbox_post(&L, &req), AMP_OK);
	OCM->req.hdr.length = AMP_MBOX_CAPACITY + 4;
	CHECK_EQ(amp_servo_mbox_poll(&S, &sr), AMP_E_PROTO);
	CHECK_EQ(amp_linux_mbox_poll(&L, &resp), AMP_OK);
	CHECK_EQ(resp.status, AMP_E_PROTO);
	/* bad magic, bad version, other epoch */
	CHECK_EQ(amp_linux_mbox_post(&L, &req), AMP_OK);
	OCM->req.hdr.magic = 0;
	CHECK_EQ(amp_servo_mbox_poll(&S, &sr), AMP_E_PROTO);
	CHECK_EQ(amp_linux_mbox_poll(&L, &resp), AMP_OK);
	CHECK_EQ(amp_linux_mbox_post(&L, &req), AMP_OK);
	OCM->req.hdr.version = 99;
	CHECK_EQ(amp_servo_mbox_poll(&S, &sr), AMP_E_PROTO);
	CHECK_EQ(amp_linux_mbox_poll(&L, &resp), AMP_OK);
	CHECK_EQ(amp_linux_mbox_post(&L, &req), AMP_OK);
	OCM->req.hdr.epoch++;
	CHECK_EQ(amp_servo_mbox_poll(&S, &sr), AMP_E_PROTO);
	CHECK_EQ(amp_linux_mbox_poll(&L, &resp), AMP_OK);
	CHECK_EQ(S.st.mbox_err, 5);

	/* corrupted response payload / header: Linux refuses it */
	CHECK_EQ(amp_linux_mbox_post(&L, &req), AMP_OK);
	CHECK_EQ(amp_servo_mbox_poll(&S, &sr), 1);
	CHECK_EQ(amp_servo_mbox_respond(&S, 0, out, 32), AMP_OK);
	OCM->resp.payload[31] ^= 1;
	CHECK_EQ(amp_linux_mbox_poll(&L, &resp), AMP_E_PROTO);
	CHECK_EQ(amp_linux_mbox_post(&L, &req), AMP_OK);
	CHECK_EQ(amp_servo_mbox_poll(&S, &sr), 1);
	CHECK_EQ(amp_servo_mbox_respond(&S, 0, out, 32), AMP_OK);
	OCM->resp.hdr.length = AMP_MBOX_CAPACITY + 32;
	CHECK_EQ(amp_linux_mbox_poll(&L, &resp), AMP_E_PROTO);
	/* an answer to another request (sequence mismatch), CRC intact */
	CHECK_EQ(amp_linux_mbox_post(&L, &req), AMP_OK);
	CHECK_EQ(amp_servo_mbox_poll(&S, &sr), 1);
	S.mbox_seq--;
	CHECK_EQ(amp_servo_mbox_respond(&S, 0, out, 8), AMP_OK);
	CHECK_EQ(amp_linux_mbox_poll(&L, &resp), AMP_E_PROTO);

	/* timeout: the servo does not answer in time; the next call finds it
	 * still busy; once the servo answers the old one, calls work again */
	CHECK_EQ(amp_linux_mbox_call(&L, &req, &resp, 2000), AMP_E_TIMEOUT);
	CHECK_EQ(amp_linux_mbox_call(&L, &req, &resp, 2000), AMP_E_BUSY);
	CHECK_EQ(amp_servo_mbox_poll(&S, &sr), 1);
	CHECK_EQ(amp_servo_mbox_respond(&S, 0, NULL, 0), AMP_OK);
	CHECK_EQ(amp_linux_mbox_post(&L, &req), AMP_OK);
	CHECK_EQ(amp_servo_mbox_poll(&S, &sr), 1);
	CHECK_EQ(amp_servo_mbox_respond(&S, 3, out, 4), AMP_OK);
	CHECK_EQ(amp_linux_mbox_poll(&L, &resp), AMP_OK);
	CHECK_EQ(resp.status, 3);

	/* NULL and inconsistent arguments from the local caller */
	CHECK_EQ(amp_linux_mbox_post(NULL, &req), AMP_E_INVAL);
	CHECK_EQ(amp_linux_mbox_post(&L, NULL), AMP_E_INVAL);
	CHECK_EQ(amp_linux_mbox_poll(&L, NULL), AMP_E_INVAL);
	CHECK_EQ(amp_linux_cycle(NULL, NULL, 0, 0, NULL), AMP_E_INVAL);
	resp.data = NULL;
	CHECK_EQ(amp_linux_mbox_poll(&L, &resp), AMP_E_INVAL);
	resp.data = in;
	CHECK_EQ(amp_linux_mbox_post(&L, &req), AMP_OK);
	CHECK_EQ(amp_servo_mbox_poll(&S, &sr), 1);
	CHECK_EQ(amp_servo_mbox_respond(&S, 0, NULL, 4), AMP_E_INVAL);
	CHECK_EQ(amp_servo_mbox_respond(&S, 0, NULL, 0), AMP_OK);
	CHECK_EQ(amp_linux_mbox_poll(&L, &resp), AMP_OK);
	CHECK_EQ(resp.length, 0);

	/* servo absent or faulted: calls fail at once with the reason */
	amp_servo_set_state(&S, AMP_SSTATE_FAULT, 1);
	CHECK_EQ(amp_linux_mbox_call(&L, &req, &resp, 1000), AMP_E_PEER_ERROR);
	CHECK_EQ(amp_linux_init(&L, ocm_buf, sizeof(ocm_buf), 0), AMP_OK);
	CHECK_EQ(amp_linux_mbox_call(&L, &req, &resp, 1000), AMP_E_PEER_ABSENT);
	/* the servo's state word says OFFLINE while a request is out: only
	 * init writes OFFLINE, so with this epoch it is a peer error (a stray
	 * write), final for the request */
	CHECK_EQ(amp_servo_attach(&S, ocm_buf, sizeof(ocm_buf)), AMP_OK);
	CHECK_EQ(amp_linux_mbox_post(&L, &req), AMP_OK);
	amp_servo_set_state(&S, AMP_SSTATE_OFFLINE, 0);
	CHECK_EQ(amp_linux_mbox_poll(&L, &resp), AMP_E_PEER_ERROR);
}

static void test_peer_info(void)
{
	struct amp_peer_info pi;
	struct amp_rx_info rx;

	/* arguments */
	CHECK_EQ(amp_linux_peer_info(NULL, sizeof(ocm_buf), &pi), AMP_E_INVAL);
	CHECK_EQ(amp_linux_peer_info(ocm_buf, sizeof(ocm_buf), NULL), AMP_E_INVAL);
	CHECK_EQ(amp_linux_peer_info(ocm_buf + 4, sizeof(ocm_buf) - 4, &pi), AMP_E_INVAL);
	CHECK_EQ(amp_linux_peer_info(ocm_buf, AMP_OCM_SIZE - 1, &pi), AMP_E_INVAL);

	/* a region nobody initialised: the words as they are */
	memset(ocm_buf, 0, sizeof(ocm_buf));
	OCM->servo_line.state = AMP_SSTATE_FAULT;
	OCM->servo_line.fault = 0x1234u;
	OCM->servo_line.epoch = 9;
	OCM->servo_line.attach_count = 4;
	OCM->servo_line.heartbeat = 77;
	CHECK_EQ(amp_linux_peer_info(ocm_buf, AMP_OCM_SIZE, &pi), AMP_OK);
	CHECK_EQ(pi.state, AMP_SSTATE_FAULT);
	CHECK_EQ(pi.fault, 0x1234u);
	CHECK_EQ(pi.epoch, 9);
	CHECK_EQ(pi.attach_count, 4);
	CHECK_EQ(pi.heartbeat, 77);

	/* a live link: what the servo published */
	fresh_pair(0);
	CHECK_EQ(amp_linux_peer_info(ocm_buf, sizeof(ocm_buf), &pi), AMP_OK);
	CHECK_EQ(pi.state, AMP_SSTATE_RUNNING);
	CHECK_EQ(pi.fault, 0);
	CHECK_EQ(pi.epoch, L.epoch);
	CHECK_EQ(pi.attach_count, 1);
	CHECK_EQ(amp_servo_cycle_rx(&S, 0, &rx), AMP_OK);
	CHECK_EQ(amp_linux_peer_info(ocm_buf, sizeof(ocm_buf), &pi), AMP_OK);
	CHECK_EQ(pi.heartbeat, S.heartbeat);
	amp_servo_set_state(&S, AMP_SSTATE_SAFESTOP, 55);
	CHECK_EQ(amp_linux_peer_info(ocm_buf, sizeof(ocm_buf), &pi), AMP_OK);
	CHECK_EQ(pi.state, AMP_SSTATE_SAFESTOP);
	CHECK_EQ(pi.fault, 55);
	CHECK_EQ(amp_servo_attach(&S, ocm_buf, sizeof(ocm_buf)), AMP_OK);
	CHECK_EQ(amp_linux_peer_info(ocm_buf, sizeof(ocm_buf), &pi), AMP_OK);
	CHECK_EQ(pi.attach_count, 2);
}

static void test_wd_limit(void)
{
	struct amp_cmd_axis a[1];
	struct amp_rx_info rx;
	int rc = AMP_OK;

	CHECK_EQ(amp_linux_set_wd_limit(NULL, 5), AMP_E_INVAL);
	fresh_pair(100);
	CHECK_EQ(amp_linux_set_wd_limit(&L, 1000001), AMP_E_INVAL);
	CHECK_EQ(L.wd.limit, 100);
	CHECK_EQ(amp_linux_set_wd_limit(&L, 0), AMP_OK);
	CHECK_EQ(L.wd.limit, AMP_WD_LIMIT_DEFAULT);
	CHECK_EQ(amp_linux_set_wd_limit(&L, 3), AMP_OK);
	/* the servo's heartbeat stands still: stalled after the new limit */
	fill_cmd(a, 1, 0);
	for (int i = 0; i < 3 && rc == AMP_OK; i++)
		rc = amp_linux_cycle(&L, a, 1, 0, &rx);
	CHECK_EQ(rc, AMP_OK);
	CHECK_EQ(amp_linux_cycle(&L, a, 1, 0, &rx), AMP_E_STALLED);
}

static void test_mbox_cancel(void)
{
	struct amp_mbox_req sr;
	uint32_t in[4] = { 0 }, out = 0;
	struct amp_msg req = { 5, 0, 4, 4, &out };
	struct amp_msg resp = { 0, 0, 0, sizeof(in), in };

	fresh_pair(0);
	CHECK_EQ(amp_linux_mbox_cancel(NULL), AMP_E_INVAL);
	CHECK_EQ(amp_linux_mbox_cancel(&L), AMP_E_INVAL);	/* nothing pending */
	CHECK_EQ(L.st.mbox_err, 0);

	/* the caller gives up: counted, nothing pending any more */
	CHECK_EQ(amp_linux_mbox_post(&L, &req), AMP_OK);
	CHECK_EQ(amp_linux_mbox_poll(&L, &resp), AMP_E_BUSY);
	CHECK_EQ(amp_linux_mbox_cancel(&L), AMP_OK);
	CHECK_EQ(L.st.mbox_err, 1);
	CHECK_EQ(L.mbox_pending, 0);
	CHECK_EQ(amp_linux_mbox_poll(&L, &resp), AMP_E_INVAL);
	CHECK_EQ(amp_linux_mbox_cancel(&L), AMP_E_INVAL);
	CHECK_EQ(L.st.mbox_err, 1);

	/* the servo still holds the token: busy until it answers the old one */
	CHECK_EQ(amp_linux_mbox_post(&L, &req), AMP_E_BUSY);
	CHECK_EQ(amp_servo_mbox_poll(&S, &sr), 1);
	CHECK_EQ(amp_servo_mbox_respond(&S, 0, NULL, 0), AMP_OK);

	/* then the link works again, and the late answer is not taken */
	CHECK_EQ(amp_linux_mbox_post(&L, &req), AMP_OK);
	CHECK_EQ(amp_servo_mbox_poll(&S, &sr), 1);
	CHECK_EQ(sr.command, 5);
	CHECK_EQ(amp_servo_mbox_respond(&S, 2, &out, 4), AMP_OK);
	CHECK_EQ(amp_linux_mbox_poll(&L, &resp), AMP_OK);
	CHECK_EQ(resp.status, 2);
	CHECK_EQ(resp.length, 4);
	CHECK_EQ(L.st.mbox_ok, 1);
	CHECK_EQ(L.st.mbox_err, 1);
}

/*
 * Issue 13, item 3: the Linux watchdog watches the servo's heartbeat
 * whatever its state word says, once the servo has attached in this
 * epoch. A servo that writes FAULT (or garbage, or OFFLINE, or corrupts
 * its epoch word) and then hangs is AMP_E_STALLED after wd_limit cycles,
 * like any other hang; a faulted or garbled servo that still beats is
 * AMP_E_PEER_ERROR; before the first attach nothing is a stall.
 */
static int cycles_until_stalled(int max, int *first_rc)
{
	struct amp_cmd_axis a[1];
	struct amp_rx_info rx;
	int n, rc = AMP_OK;

	fill_cmd(a, 1, 0);
	for (n = 1; n <= max; n++) {
		rc = amp_linux_cycle(&L, a, 1, 0, &rx);
		if (n == 1 && first_rc)
			*first_rc = rc;
		if (rc == AMP_E_STALLED)
			return n;
	}
	return -1;
}

static void beat_once(void)
{
	struct amp_fb_axis f[1];
	struct amp_rx_info rx;

	memset(f, 0, sizeof(f));
	(void)amp_servo_cycle_rx(&S, 0, &rx);
	CHECK_EQ(amp_servo_cycle_tx(&S, f, 1, 0, 0), AMP_OK);
}

static void test_watchdog_any_peer_state(void)
{
	static const uint32_t states[] = { AMP_SSTATE_FAULT, 0xdeadbeefu, AMP_SSTATE_OFFLINE };
	struct amp_cmd_axis a[1];
	struct amp_rx_info rx;
	int first;

	fill_cmd(a, 1, 0);
	/* before the servo ever attached: absent, never a stall */
	memset(ocm_buf, 0, sizeof(ocm_buf));
	CHECK_EQ(amp_linux_init(&L, ocm_buf, sizeof(ocm_buf), 4), AMP_OK);
	CHECK_EQ(cycles_until_stalled(100, &first), -1);
	CHECK_EQ(first, AMP_E_PEER_ABSENT);

	for (size_t k = 0; k < sizeof(states) / sizeof(states[0]); k++) {
		fresh_pair(4);
		beat_once();
		CHECK_EQ(amp_linux_cycle(&L, a, 1, 0, &rx), AMP_OK);
		/* the servo writes the state word and hangs: the 4th (wd_limit)
		 * Linux cycle after the one that saw its last beat detects it */
		OCM->servo_line.state = states[k];
		CHECK_EQ(cycles_until_stalled(10, &first), 4);
		CHECK_EQ(first, AMP_E_PEER_ERROR);	/* OFFLINE too: only init writes it */
		/* stays detected until the servo comes back */
		CHECK_EQ(amp_linux_cycle(&L, a, 1, 0, &rx), AMP_E_STALLED);
		/* recovery: the restarted servo attaches again (same epoch) */
		CHECK_EQ(amp_servo_attach(&S, ocm_buf, sizeof(ocm_buf)), AMP_OK);
		beat_once();
		CHECK_EQ(amp_linux_cycle(&L, a, 1, 0, &rx), AMP_OK);
		CHECK_EQ(cycles_until_stalled(3, 0), -1);	/* re-primed */
	}

	/* a garbled state word while the servo still beats: a peer error
	 * (not "absent"), never a stall */
	fresh_pair(4);
	OCM->servo_line.state = 0x12345678u;
	for (int n = 0; n < 20; n++) {
		amp_servo_heartbeat(&S);
		CHECK_EQ(amp_linux_cycle(&L, a, 1, 0, &rx), AMP_E_PEER_ERROR);
	}
	CHECK_EQ(amp_linux_peer(&L), AMP_E_PEER_ERROR);

	/* the servo's epoch word corrupted, then the servo hangs */
	fresh_pair(4);
	beat_once();
	CHECK_EQ(amp_linux_cycle(&L, a, 1, 0, &rx), AMP_OK);
	OCM->servo_line.epoch ^= 0x5a5a0000u;
	CHECK_EQ(cycles_until_stalled(10, &first), 4);
	CHECK_EQ(first, AMP_E_PEER_ERROR);

	/* the servo's epoch word corrupted while the servo still beats (a
	 * stray write from either core): once the servo has attached in this
	 * epoch, another epoch word is a peer error, which servod recovers,
	 * never "absent", which it would wait on forever (measured on the
	 * board: devmem 0xffff0044 32 0xdeadbeef left the link down for good) */
	fresh_pair(4);
	beat_once();
	CHECK_EQ(amp_linux_cycle(&L, a, 1, 0, &rx), AMP_OK);
	OCM->servo_line.epoch = 0xdeadbeefu;
	for (int n = 0; n < 20; n++) {
		amp_servo_heartbeat(&S);
		CHECK_EQ(amp_linux_cycle(&L, a, 1, 0, &rx), AMP_E_PEER_ERROR);
	}
	CHECK_EQ(amp_linux_peer(&L), AMP_E_PEER_ERROR);
	/* the restarted servo attaches again and rewrites the word; it is a
	 * restart (attach 2), and its feedback continues the sequence Linux
	 * knows (a sequence back at 0 would be "reordered" for good) */
	for (int n = 0; n < 3; n++) {
		beat_once();
		(void)amp_linux_cycle(&L, a, 1, 0, &rx);
	}
	CHECK_EQ(amp_servo_attach(&S, ocm_buf, sizeof(ocm_buf)), AMP_OK);
	CHECK_EQ(OCM->servo_line.attach_count, 2);
	CHECK_EQ(OCM->servo_line.epoch, L.epoch);
	for (int n = 0; n < 5; n++) {
		beat_once();
		CHECK_EQ(amp_linux_cycle(&L, a, 1, 0, &rx), AMP_OK);
		CHECK_EQ(rx.status, AMP_RX_FRESH);
	}
	/* before any attach in this epoch another epoch word is still just
	 * "absent" (the servo of the previous epoch) */
	memset(ocm_buf, 0, sizeof(ocm_buf));
	CHECK_EQ(amp_linux_init(&L, ocm_buf, sizeof(ocm_buf), 4), AMP_OK);
	OCM->servo_line.epoch = 0xdeadbeefu;
	OCM->servo_line.state = AMP_SSTATE_RUNNING;
	CHECK_EQ(amp_linux_peer(&L), AMP_E_PEER_ABSENT);
}

/* The servo stops on request (remoteproc's stop): it writes STOPPING,
 * then its heartbeat ends. Never a stall, however long remoteproc takes to
 * say offline; a servo that beats again in this epoch (a restart) has its
 * watchdog afresh. */
static void test_stopping_is_no_stall(void)
{
	struct amp_cmd_axis a[1];
	struct amp_rx_info rx;

	fill_cmd(a, 1, 0);
	fresh_pair(4);
	beat_once();
	CHECK_EQ(amp_linux_cycle(&L, a, 1, 0, &rx), AMP_OK);
	amp_servo_set_state(&S, AMP_SSTATE_STOPPING, 0);
	CHECK_EQ(amp_linux_peer(&L), AMP_E_PEER_STOPPING);
	for (int n = 0; n < 100; n++)
		CHECK_EQ(amp_linux_cycle(&L, a, 1, 0, &rx), AMP_E_PEER_STOPPING);
	/* a mailbox call fails at once with the reason */
	{
		uint32_t w = 0;
		struct amp_msg req = { 1u, 0, 4u, 4u, &w }, resp = { 0, 0, 0, 4u, &w };

		CHECK_EQ(amp_linux_mbox_call(&L, &req, &resp, 1000), AMP_E_PEER_STOPPING);
	}
	/* restarted (attach 2, same epoch): watched again from its attach */
	CHECK_EQ(amp_servo_attach(&S, ocm_buf, sizeof(ocm_buf)), AMP_OK);
	beat_once();
	CHECK_EQ(amp_linux_cycle(&L, a, 1, 0, &rx), AMP_OK);
	CHECK_EQ(cycles_until_stalled(10, 0), 4);
}

/* A semaphore word that is neither IDLE nor BUSY (a stray write from
 * either core) is repaired by Linux and counted, never left to block the
 * exchange or the mailbox for good. */
static void test_garbled_semaphores(void)
{
	struct amp_cmd_axis a[1];
	struct amp_rx_info rx;
	struct amp_mbox_req q;
	uint8_t buf[16];
	struct amp_msg req = { .command = 7, .length = 4, .data = buf };
	struct amp_msg resp = { .capacity = sizeof(buf), .data = buf };

	fill_cmd(a, 1, 0);
	fresh_pair(4);
	memset(buf, 0x11, sizeof(buf));
	beat_once();
	CHECK_EQ(amp_linux_cycle(&L, a, 1, 0, &rx), AMP_OK);
	OCM->cyc_sem.sem = 0x5a5a5a5au;
	beat_once();
	CHECK_EQ(amp_linux_cycle(&L, a, 1, 0, &rx), AMP_OK);
	CHECK_EQ(L.st.sem_corrupt, 1);
	CHECK_EQ(OCM->cyc_sem.sem, AMP_SEM_BUSY);
	beat_once();
	CHECK_EQ(OCM->cyc_sem.sem, AMP_SEM_IDLE);	/* the servo handed it back */
	CHECK_EQ(amp_linux_cycle(&L, a, 1, 0, &rx), AMP_OK);
	CHECK_EQ(rx.status, AMP_RX_FRESH);
	CHECK_EQ(L.st.sem_corrupt, 1);

	OCM->mbox_sem.sem = 0xa5a5a5a5u;
	CHECK_EQ(amp_linux_mbox_post(&L, &req), AMP_OK);
	CHECK_EQ(L.st.sem_corrupt, 2);
	CHECK_EQ(amp_servo_mbox_poll(&S, &q), 1);
	CHECK_EQ(amp_servo_mbox_respond(&S, 0, buf, 4), AMP_OK);
	CHECK_EQ(amp_linux_mbox_poll(&L, &resp), AMP_OK);
	CHECK_EQ(resp.length, 4);
	/* a real BUSY still means "the servo has the token" */
	OCM->mbox_sem.sem = AMP_SEM_BUSY;
	CHECK_EQ(amp_linux_mbox_post(&L, &req), AMP_E_BUSY);
	CHECK_EQ(L.st.sem_corrupt, 2);
}

static void test_layout_constants(void)
{
	/* the documented layout (docs/amp-protocol.md), default config */
	CHECK_EQ(sizeof(struct amp_ocm), AMP_OCM_SIZE);
	CHECK_EQ(AMP_OCM_SIZE % AMP_CACHE_LINE, 0);
	CHECK_EQ(offsetof(struct amp_ocm, cmd) % AMP_CACHE_LINE, 0);
	CHECK_EQ(offsetof(struct amp_ocm, fb[1]) % AMP_CACHE_LINE, 0);
	CHECK_EQ(offsetof(struct amp_ocm, cmd[1]) % AMP_CACHE_LINE, 0);
	CHECK_EQ(offsetof(struct amp_ocm, resp) % AMP_CACHE_LINE, 0);
#if AMP_MAX_AXES == 8 && AMP_MBOX_CAPACITY == 512 && AMP_CACHE_LINE == 32
	CHECK_EQ(AMP_OCM_SIZE, 2080);
#endif
	printf("layout: AMP_MAX_AXES=%d AMP_MBOX_CAPACITY=%d size=%u bytes\n",
	       AMP_MAX_AXES, AMP_MBOX_CAPACITY, (unsigned)AMP_OCM_SIZE);
}

int main(void)
{
	test_crc();
	test_strerror();
	test_watchdog();
	test_init_args();
	test_attach_checks();
	test_peer_and_epoch();
	test_periodic();
	test_watchdogs_both_ways();
	test_mailbox();
	test_peer_info();
	test_wd_limit();
	test_mbox_cancel();
	test_watchdog_any_peer_state();
	test_stopping_is_no_stall();
	test_garbled_semaphores();
	test_layout_constants();
	return check_summary("amp_lib unit");
}
