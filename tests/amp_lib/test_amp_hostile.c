// SPDX-License-Identifier: MIT
/*
 * amp_lib against a hostile peer that rewrites OCM while it is being read
 * (issue 13, finding 10). Built with the posix port's load hook
 * (AMP_PORT_TEST_LOAD_HOOK): every load amp_lib makes from the region goes
 * through amp_port_test_load_hook, which plays the peer at an exact point
 * (right after the first load from a given range it rewrites another
 * word), so each race below happens every run, deterministically.
 *
 * The rule under test: what crosses from the peer is copied once into
 * private memory, the copy is validated, the copy is used. A frame whose
 * CRC does not match the bytes handed to the caller is never accepted.
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

/* The hostile peer: after the first load from [lo, hi), *target ^= xor. */
static struct {
	const uint32_t *lo, *hi;
	uint32_t *target;
	uint32_t xor;
	int armed, fired;
	const uint32_t *count_addr;	/* loads of this word are counted */
	unsigned count;
} hk;

uint32_t amp_port_test_load_hook(const uint32_t *p, uint32_t v)
{
	if (p == hk.count_addr)
		hk.count++;
	if (hk.armed && p >= hk.lo && p < hk.hi) {
		hk.armed = 0;
		hk.fired = 1;
		__atomic_store_n(hk.target, __atomic_load_n(hk.target, __ATOMIC_RELAXED) ^ hk.xor,
				 __ATOMIC_RELAXED);
	}
	return v;
}

static void arm(const void *lo, uint32_t bytes, uint32_t *target, uint32_t xor)
{
	hk.lo = lo;
	hk.hi = (const uint32_t *)lo + bytes / 4u;
	hk.target = target;
	hk.xor = xor;
	hk.fired = 0;
	hk.armed = 1;
}

static void disarm(void)
{
	hk.armed = 0;
	hk.count_addr = NULL;
	hk.count = 0;
}

static void fresh_pair(void)
{
	disarm();
	memset(ocm_buf, 0, sizeof(ocm_buf));
	CHECK_EQ(amp_linux_init(&L, ocm_buf, sizeof(ocm_buf), 0), AMP_OK);
	CHECK_EQ(amp_servo_attach(&S, ocm_buf, sizeof(ocm_buf)), AMP_OK);
}

/* Linux reads the servo's answer; the servo rewrites its last payload word
 * right after Linux's first payload load (old code: after the CRC pass
 * over OCM, before the copy). */
static void test_response_rewritten_during_read(void)
{
	uint8_t out[64], in[64];
	uint32_t req_word = 1;
	struct amp_msg req = { .command = 3, .length = 4, .data = &req_word };
	struct amp_msg resp = { .capacity = sizeof(in), .data = in };
	struct amp_mbox_req sr;
	uint32_t err0;
	int rc;

	fresh_pair();
	for (uint32_t i = 0; i < sizeof(out); i++)
		out[i] = (uint8_t)(i * 5 + 1);
	CHECK_EQ(amp_linux_mbox_post(&L, &req), AMP_OK);
	CHECK_EQ(amp_servo_mbox_poll(&S, &sr), 1);
	CHECK_EQ(amp_servo_mbox_respond(&S, 0, out, sizeof(out)), AMP_OK);
	memset(in, 0, sizeof(in));
	err0 = L.st.mbox_err;
	arm(OCM->resp.payload, sizeof(out), (uint32_t *)(void *)&OCM->resp.payload[60], 0xffu);
	rc = amp_linux_mbox_poll(&L, &resp);
	CHECK(hk.fired);
	/* accepted only if what the caller got is what the CRC covered */
	CHECK(rc != AMP_OK || memcmp(in, out, sizeof(out)) == 0);
	CHECK_EQ(rc, AMP_E_PROTO);
	CHECK_EQ(L.st.mbox_err, err0 + 1u);
	disarm();
}

/* The servo validated a request; Linux then rewrites it in OCM before the
 * application has read it: the application must still see what passed. */
static void test_request_rewritten_after_validation(void)
{
	uint8_t out[32];
	struct amp_msg req = { .command = 4, .length = sizeof(out), .data = out };
	struct amp_mbox_req sr;

	fresh_pair();
	for (uint32_t i = 0; i < sizeof(out); i++)
		out[i] = (uint8_t)(0x40 + i);
	CHECK_EQ(amp_linux_mbox_post(&L, &req), AMP_OK);
	CHECK_EQ(amp_servo_mbox_poll(&S, &sr), 1);
	for (uint32_t i = 0; i < sizeof(out); i++)	/* the peer, afterwards */
		OCM->req.payload[i] = 0xee;
	CHECK_EQ(sr.length, sizeof(out));
	CHECK(memcmp((const void *)sr.payload, out, sizeof(out)) == 0);
	CHECK_EQ(amp_servo_mbox_respond(&S, 0, NULL, 0), AMP_OK);
}

/* Linux rewrites the request while the servo reads it: refused. Every byte
 * the servo takes from OCM goes through the port's accessor (the hook
 * fires); the old code's CRC pass read OCM behind the port's back. */
static void test_request_rewritten_during_read(void)
{
	uint8_t out[32];
	struct amp_msg req = { .command = 5, .length = sizeof(out), .data = out };
	struct amp_msg resp = { 0 };
	struct amp_mbox_req sr;
	int rc;

	fresh_pair();
	memset(out, 0x11, sizeof(out));
	CHECK_EQ(amp_linux_mbox_post(&L, &req), AMP_OK);
	arm(OCM->req.payload, sizeof(out), (uint32_t *)(void *)&OCM->req.payload[28], 0x80u);
	rc = amp_servo_mbox_poll(&S, &sr);
	CHECK(hk.fired);
	CHECK(rc != 1 || memcmp((const void *)sr.payload, out, sizeof(out)) == 0);
	CHECK_EQ(rc, AMP_E_PROTO);
	disarm();
	CHECK_EQ(amp_linux_mbox_poll(&L, &resp), AMP_OK);
	CHECK_EQ(resp.status, AMP_E_PROTO);
}

/* A periodic record: the peer changes n_axes right after it was read; the
 * record taken is the copy, validated and within AMP_MAX_AXES. */
static void test_record_count_rewritten_after_read(void)
{
	struct amp_cmd_axis a[2] = { { AMP_AXIS_ENABLE, 100, 0, 0 }, { AMP_AXIS_ENABLE, 200, 0, 0 } };
	struct amp_rx_info rx;
	uint32_t *n;

	fresh_pair();
	CHECK_EQ(amp_linux_cycle(&L, a, 2, 0, &rx), AMP_OK);
	n = &OCM->cmd[L.cmd_seq & 1u].n_axes;
	arm(n, 4, n, 2u ^ 99u);
	CHECK_EQ(amp_servo_cycle_rx(&S, 0, &rx), AMP_OK);
	CHECK(hk.fired);
	CHECK_EQ(rx.status, AMP_RX_FRESH);
	CHECK_EQ(S.cmd.n_axes, 2);
	CHECK_EQ(S.cmd.axis[1].target_pos, 200);
	disarm();
}

/* Linux's cycle reads the servo's attach_count once (it was read twice:
 * compared, then re-read to keep, so the peer could change it between). */
static void test_attach_count_read_once(void)
{
	struct amp_rx_info rx;

	fresh_pair();
	hk.count_addr = &OCM->servo_line.attach_count;
	hk.count = 0;
	(void)amp_linux_cycle(&L, NULL, 0, 0, &rx);
	CHECK_EQ(hk.count, 1);
	disarm();
}

int main(void)
{
	test_response_rewritten_during_read();
	test_request_rewritten_after_validation();
	test_request_rewritten_during_read();
	test_record_count_rewritten_after_read();
	test_attach_count_read_once();
	return check_summary("test_amp_hostile");
}
