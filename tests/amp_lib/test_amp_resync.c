// SPDX-License-Identifier: MIT
/*
 * Issue 20, item 4: a re-attach resynchronises the periodic line.
 *
 * Both sides run in one thread over a local buffer standing in for OCM,
 * the servo as rpu_app/src/link.c drives it (attach in the background
 * loop, retried while refused; cycle_rx / cycle_tx every cycle while
 * attached; detached on AMP_E_PEER_ABSENT), Linux as servod's cycle
 * thread does (amp_linux_cycle every cycle, Linux first, as both take the
 * same interrupt and the servo answers within it).
 *
 * The report: after 1000 cycles, a stray write of 0 to fb_pub while the
 * servo was down, then a re-attach, left 999 cycles of AMP_RX_INVALID
 * with amp_linux_cycle returning AMP_OK: no feedback, and nothing for the
 * watchdog to act on. The rule checked here: whatever the shared words
 * say after a re-attach, feedback resumes within 2 cycles (3 for a word of
 * Linux's own header and line, which its next cycle writes again before
 * the servo can attach), or amp_linux_cycle returns an error servod's
 * watchdog acts on (AMP_E_STALLED or AMP_E_FEEDBACK); and a run of refused
 * feedback reads is never AMP_OK for more than wd_limit cycles, re-attach
 * or not.
 */
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "amp/amp.h"
#include "check.h"

static _Alignas(64) uint8_t ocm_buf[AMP_OCM_SIZE + 64];
#define OCM ((struct amp_ocm *)ocm_buf)
#define OCM_WORDS (AMP_OCM_SIZE / 4u)

static uint32_t *word(uint32_t i)
{
	return (uint32_t *)(void *)ocm_buf + i;
}

static struct amp_linux L;
static struct amp_servo S;

/* The servo as the firmware runs it. */
static struct {
	int up;		/* the core runs (0: crashed / stopped) */
	int attached;
	int rc;		/* last amp_servo_cycle_rx result */
	struct amp_rx_info rx;	/* its command read */
} sv;

/* What one cycle gave on each side. */
struct step {
	int rc;			/* amp_linux_cycle */
	struct amp_rx_info rx;	/* Linux's feedback read */
	int servo_ran;		/* the servo exchanged in this cycle */
	uint32_t servo_rx;	/* the servo's command read (if it ran) */
};

static int taken(uint32_t status)
{
	return status == AMP_RX_FRESH || status == AMP_RX_MISSED;
}

/* link_poll: attach while not attached (the firmware retries every few
 * cycles; here every cycle). */
static void servo_poll(void)
{
	if (sv.up && !sv.attached && amp_servo_attach(&S, ocm_buf, sizeof(ocm_buf)) == AMP_OK)
		sv.attached = 1;
}

/* link_cycle: commands in, feedback out (its cycle counter as position,
 * so Linux's copy says which servo cycle it came from). */
static int servo_cycle(void)
{
	struct amp_fb_axis fb[1];

	if (!sv.up || !sv.attached)
		return 0;
	sv.rc = amp_servo_cycle_rx(&S, 0, &sv.rx);
	if (sv.rc == AMP_E_PEER_ABSENT) {
		sv.attached = 0;
		return 0;
	}
	memset(fb, 0, sizeof(fb));
	fb[0].actual_pos = (int32_t)S.cycle;
	CHECK_EQ(amp_servo_cycle_tx(&S, fb, 1, S.cycle, 0), AMP_OK);
	return 1;
}

static struct step cycle(void)
{
	struct amp_cmd_axis a[1] = { { AMP_AXIS_ENABLE, 0, 0, 0 } };
	struct step st;

	memset(&st, 0, sizeof(st));
	a[0].target_pos = (int32_t)L.cycle;
	st.rc = amp_linux_cycle(&L, a, 1, 0, &st.rx);
	st.servo_ran = servo_cycle();
	st.servo_rx = sv.rx.status;
	servo_poll();
	return st;
}

static void start(uint32_t wd_limit)
{
	memset(ocm_buf, 0, sizeof(ocm_buf));
	memset(&sv, 0, sizeof(sv));
	CHECK_EQ(amp_linux_init(&L, ocm_buf, sizeof(ocm_buf), wd_limit), AMP_OK);
	sv.up = 1;
	servo_poll();
	CHECK_EQ(sv.attached, 1);
}

/* n healthy cycles: every one AMP_OK, feedback and commands fresh from the
 * second on. Returns the number of cycles that were not. */
static unsigned healthy(unsigned n)
{
	unsigned bad = 0;

	for (unsigned i = 0; i < n; i++) {
		struct step st = cycle();
		int first = L.cycle == 1;

		if (st.rc != AMP_OK || (!first && !taken(st.rx.status)) || !st.servo_ran ||
		    !taken(st.servo_rx))
			bad++;
	}
	return bad;
}

/* The servo core stops (crash, hang): no cycle, no heartbeat. */
static void servo_down(void)
{
	sv.up = 0;
	sv.attached = 0;
}

/* remoteproc starts it again: it attaches in its background loop. */
static void servo_restart(void)
{
	sv.up = 1;
	sv.attached = 0;
	servo_poll();
}

/*
 * The report, exactly: 1000 cycles, the servo goes down, a stray write of
 * 0 to fb_pub, the servo re-attaches. Feedback resumes within 2 cycles
 * and stays (the next 999 cycles were AMP_RX_INVALID with AMP_OK).
 */
static void test_report_stray_zero_fb_pub(void)
{
	unsigned first = 0, after = 0, silent = 0;
	uint32_t invalid0;

	start(0);	/* servod's default watchdog limit */
	CHECK_EQ(healthy(1000), 0);
	CHECK_EQ(OCM->servo_line.fb_pub, 1000);
	CHECK_EQ(L.fb_seq, 999);
	servo_down();
	for (int i = 0; i < 2; i++)	/* Linux runs on: not yet a stall */
		CHECK_EQ(cycle().rc, AMP_OK);
	OCM->servo_line.fb_pub = 0;	/* the stray write */
	servo_restart();
	CHECK_EQ(sv.attached, 1);
	CHECK_EQ(OCM->servo_line.attach_count, 2);
	invalid0 = L.st.invalid;
	for (unsigned n = 1; n <= 1000; n++) {
		struct step st = cycle();

		if (!first && st.rc == AMP_OK && taken(st.rx.status))
			first = n;
		if (first && (st.rc != AMP_OK || st.rx.status != AMP_RX_FRESH))
			after++;
		if (st.rc == AMP_OK && st.rx.status == AMP_RX_INVALID)
			silent++;
	}
	printf("report: feedback resumed at cycle %u after the re-attach; %u cycles AMP_OK+INVALID\n",
	       first, silent);
	CHECK(first >= 1 && first <= 2);
	CHECK_EQ(after, 0);
	CHECK_EQ(silent, 0);
	CHECK_EQ(L.st.invalid, invalid0);
	/* the feedback Linux holds is the restarted servo's: the one it
	 * published in the cycle before (Linux reads before it writes) */
	CHECK_EQ(L.fb.cycle, S.cycle - 1u);
	CHECK_EQ(L.fb.axis[0].actual_pos, (int32_t)(S.cycle - 1u));
	CHECK_EQ(L.fb_seq, S.fb_seq - 1u);
}

static uint32_t rng_state = 0x2545f491u;

static uint32_t xorshift(void)
{
	uint32_t x = rng_state;

	x ^= x << 13;
	x ^= x >> 17;
	x ^= x << 5;
	return rng_state = x;
}

enum { V_ZERO, V_ONE, V_MAX, V_OLD, V_PREV, V_NEXT, V_AHEAD, V_HALF, V_RANDOM, V_KINDS };
static const char *const kind_name[V_KINDS] = {
	"0", "1", "max", "old", "cur-1", "cur+1", "cur+65536", "cur^0x80000000", "random",
};

static uint32_t hostile(int kind, uint32_t cur, uint32_t old)
{
	switch (kind) {
	case V_ZERO: return 0;
	case V_ONE: return 1;
	case V_MAX: return 0xffffffffu;
	case V_OLD: return old;		/* the word as it was earlier in the run */
	case V_PREV: return cur - 1u;
	case V_NEXT: return cur + 1u;
	case V_AHEAD: return cur + 65536u;
	case V_HALF: return cur ^ 0x80000000u;
	default: return xorshift();
	}
}

static void where(uint32_t w, char *buf, size_t n)
{
	static const struct {
		const char *name;
		size_t off, size;
	} r[] = {
		{ "hdr", offsetof(struct amp_ocm, hdr), sizeof(struct amp_ocm_header) },
		{ "linux_line", offsetof(struct amp_ocm, linux_line), sizeof(struct amp_linux_line) },
		{ "servo_line", offsetof(struct amp_ocm, servo_line), sizeof(struct amp_servo_line) },
		{ "cyc_sem", offsetof(struct amp_ocm, cyc_sem), sizeof(struct amp_sem_line) },
		{ "mbox_sem", offsetof(struct amp_ocm, mbox_sem), sizeof(struct amp_sem_line) },
		{ "cmd[0]", offsetof(struct amp_ocm, cmd[0]), sizeof(struct amp_cmd_record) },
		{ "cmd[1]", offsetof(struct amp_ocm, cmd[1]), sizeof(struct amp_cmd_record) },
		{ "fb[0]", offsetof(struct amp_ocm, fb[0]), sizeof(struct amp_fb_record) },
		{ "fb[1]", offsetof(struct amp_ocm, fb[1]), sizeof(struct amp_fb_record) },
		{ "req", offsetof(struct amp_ocm, req), sizeof(struct amp_frame) },
		{ "resp", offsetof(struct amp_ocm, resp), sizeof(struct amp_frame) },
	};
	size_t off = 4u * w;

	for (size_t i = 0; i < sizeof(r) / sizeof(r[0]); i++)
		if (off >= r[i].off && off < r[i].off + r[i].size) {
			snprintf(buf, n, "%s+0x%zx", r[i].name, off - r[i].off);
			return;
		}
	snprintf(buf, n, "0x%zx", off);
}

#define WD 8u			/* watchdog limit of the scenarios */
#define RUN (4u * WD + 8u)	/* cycles watched after the re-attach */

struct outcome {
	unsigned resumed;	/* Linux cycle (1..) of the first feedback taken with AMP_OK, 0 none */
	unsigned cmd_resumed;	/* servo cycle (1..) of the first commands taken, 0 none */
	unsigned first_err;	/* Linux cycle of the first AMP_E_STALLED / AMP_E_FEEDBACK, 0 none */
	unsigned broken;	/* after resuming: cycles not FRESH+AMP_OK, or commands not taken */
	unsigned silent_run;	/* longest run of AMP_OK / AMP_E_PEER_ERROR without feedback taken */
	unsigned ok_in_error;	/* after the first error: AMP_OK cycles without feedback taken */
};

/*
 * One scenario: a healthy run (its length varies, so both buffers take
 * their turn as the newest), the servo goes down, word w of the region is
 * written with value v, the servo is restarted and attaches (if the region
 * still lets it), then RUN cycles are watched.
 */
static struct outcome scenario(uint32_t w, int kind, uint32_t *value)
{
	static uint32_t snap[OCM_WORDS];
	unsigned warm = 16u + (w + (unsigned)kind) % 5u, servo_n = 0, run = 0;
	struct outcome o;

	memset(&o, 0, sizeof(o));
	start(WD);
	for (unsigned i = 0; i < warm; i++) {
		if (i == warm / 2u)
			memcpy(snap, ocm_buf, sizeof(snap));
		(void)cycle();
	}
	CHECK_EQ(L.st.invalid + L.st.torn, 0);
	servo_down();
	(void)cycle();
	(void)cycle();
	*value = hostile(kind, *word(w), snap[w]);
	*word(w) = *value;
	servo_restart();
	for (unsigned n = 1; n <= RUN; n++) {
		struct step st = cycle();
		int fb = taken(st.rx.status);

		if (st.servo_ran) {
			servo_n++;
			if (!o.cmd_resumed && taken(st.servo_rx))
				o.cmd_resumed = servo_n;
		}
		if (!o.resumed && st.rc == AMP_OK && fb)
			o.resumed = n;
		if (o.resumed && (st.rc != AMP_OK || st.rx.status != AMP_RX_FRESH ||
				  !st.servo_ran || !taken(st.servo_rx)))
			o.broken++;
		if (!o.first_err && (st.rc == AMP_E_STALLED || st.rc == AMP_E_FEEDBACK))
			o.first_err = n;
		if (o.first_err && st.rc == AMP_OK && !fb)
			o.ok_in_error++;
		if ((st.rc == AMP_OK || st.rc == AMP_E_PEER_ERROR) && !fb) {
			if (++run > o.silent_run)
				o.silent_run = run;
		} else {
			run = 0;
		}
	}
	return o;
}

/*
 * The generalisation: every word of the region (the periodic line's
 * publication and sequence words, semaphores, records, lines and header,
 * and the mailbox frames), each set to each hostile value while the servo
 * is down. After the re-attach, feedback (and the servo's commands)
 * resume within 2 cycles and stay (3 for the header and Linux's line:
 * Linux writes them again in its next cycle, then the servo attaches; a
 * stray write there kept the servo from attaching, AMP_E_STALLED, before
 * amp_linux_cycle wrote them every cycle), or amp_linux_cycle returns
 * AMP_E_STALLED / AMP_E_FEEDBACK within wd_limit + 2 cycles and never
 * AMP_OK without feedback afterwards; and never more than wd_limit - 1
 * cycles in a row of AMP_OK (or AMP_E_PEER_ERROR, whose feedback servod
 * still uses) without feedback taken.
 */
static void test_every_word_every_hostile_value(void)
{
	unsigned scen = 0, resumed = 0, errored = 0, failed = 0, listed = 0;
	char errs[512] = "";

	for (uint32_t w = 0; w < OCM_WORDS; w++) {
		for (int k = 0; k < V_KINDS; k++) {
			uint32_t v;
			struct outcome o = scenario(w, k, &v);
			unsigned bound = w < offsetof(struct amp_ocm, servo_line) / 4u ? 3u : 2u;
			int ok_resumed = o.resumed >= 1 && o.resumed <= bound && o.broken == 0 &&
					 o.cmd_resumed >= 1 && o.cmd_resumed <= 2;
			int ok_error = !o.resumed && o.first_err >= 1 && o.first_err <= WD + 2u &&
				       o.ok_in_error == 0;
			int ok = (ok_resumed || ok_error) && o.silent_run < WD;

			scen++;
			resumed += ok_resumed;
			errored += ok_error;
			if (ok_error && listed != w + 1u) {	/* the words, once each */
				char name[48];
				size_t len = strlen(errs);

				where(w, name, sizeof(name));
				snprintf(errs + len, sizeof(errs) - len, " %s", name);
				listed = w + 1u;
			}
			if (!ok) {
				char name[48];

				where(w, name, sizeof(name));
				if (failed++ < 40)
					fprintf(stderr, "%s := %s (0x%08x): feedback at cycle %u, commands at %u,"
						" %u broken after; first error at %u, %u AMP_OK after it;"
						" longest silent run %u\n", name, kind_name[k], v, o.resumed,
						o.cmd_resumed, o.broken, o.first_err, o.ok_in_error,
						o.silent_run);
			}
			CHECK(ok);
		}
	}
	printf("every word: %u scenarios, %u resumed within 2 (Linux's own words: 3) cycles,"
	       " %u reported an error, %u failed\nwords whose stray write ends in an error:%s\n",
	       scen, resumed, errored, failed, errs);
	CHECK_EQ(scen, OCM_WORDS * V_KINDS);
	CHECK(resumed > 0);
}

/*
 * Stray writes at once: fb_pub := 0 as in the report and the servo's
 * attach_count wound back, so that the re-attach leaves it where Linux
 * last saw it. The re-attach continues after the newest sequence in the
 * records, not after fb_pub: the feedback goes on in sequence, taken.
 * With the records' sequence words hit too (:= 0), the re-attach starts
 * again from 0 and Linux cannot tell the attach, the records look
 * reordered: the refused reads are AMP_E_FEEDBACK at the wd_limit-th cycle
 * (they were AMP_OK for ever). What servod does then (a crash reported,
 * remoteproc restarts the servo, which attaches again) brings the
 * feedback back within 2 cycles.
 */
static void test_unseen_reattach_reported(void)
{
	unsigned n, err = 0;
	struct step st;

	/* fb_pub and attach_count: nothing to report, the feedback goes on */
	start(WD);
	CHECK_EQ(healthy(100), 0);
	servo_down();
	(void)cycle();
	OCM->servo_line.fb_pub = 0;
	OCM->servo_line.attach_count -= 1u;
	servo_restart();
	CHECK_EQ(OCM->servo_line.attach_count, L.servo_attach);
	CHECK_EQ(cycle().rc, AMP_OK);	/* the restarted servo's first record */
	CHECK_EQ(healthy(20), 0);

	/* and the records' sequence words: the sequence starts again */
	start(WD);
	CHECK_EQ(healthy(100), 0);
	servo_down();
	(void)cycle();
	OCM->servo_line.fb_pub = 0;
	for (int i = 0; i < 2; i++)
		OCM->fb[i].seq_begin = OCM->fb[i].seq_end = 0;
	OCM->servo_line.attach_count -= 1u;
	servo_restart();
	CHECK_EQ(OCM->servo_line.attach_count, L.servo_attach);
	for (n = 1; n <= 3u * WD; n++) {
		st = cycle();
		CHECK(st.rc == AMP_OK || st.rc == AMP_E_FEEDBACK);
		CHECK(!taken(st.rx.status));
		if (st.rc == AMP_E_FEEDBACK && !err)
			err = n;
		if (err)
			CHECK_EQ(st.rc, AMP_E_FEEDBACK);	/* stays reported */
	}
	CHECK_EQ(err, WD);
	/* servod: report_crash, remoteproc restarts the firmware */
	servo_down();
	servo_restart();
	st = cycle();
	if (!taken(st.rx.status))
		st = cycle();
	CHECK_EQ(st.rc, AMP_OK);
	CHECK_EQ(st.rx.status, AMP_RX_FRESH);
	CHECK_EQ(healthy(20), 0);
}

/* After each feedback the servo publishes, the record is spoilt in OCM
 * (how: 0 epoch, 1 axis count, 2 seq_begin) before Linux reads it. */
static struct step cycle_spoilt(int how)
{
	struct step st = cycle();
	struct amp_fb_record *f = &OCM->fb[S.fb_seq & 1u];

	if (how == 0)
		f->epoch ^= 0x10000u;
	else if (how == 1)
		f->n_axes = AMP_MAX_AXES + 1u;
	else
		f->seq_begin++;
	return st;
}

/*
 * No re-attach at all: a servo that beats but whose every record is
 * refused (INVALID: wrong epoch, axis count; TORN) is reported at the
 * wd_limit-th refused cycle and on every cycle after, until a record is
 * taken again; refused reads between good ones are never an error.
 */
static void test_refused_streak_bounded(void)
{
	static const uint32_t expect[3] = { AMP_RX_INVALID, AMP_RX_INVALID, AMP_RX_TORN };

	for (int how = 0; how < 3; how++) {
		unsigned err = 0, n;
		struct step st;

		start(WD);
		CHECK_EQ(healthy(50), 0);
		(void)cycle_spoilt(how);	/* Linux reads it in the next cycle */
		for (n = 1; n <= 5u * WD; n++) {
			st = cycle_spoilt(how);
			CHECK_EQ(st.rx.status, expect[how]);
			CHECK_EQ(st.rc, n < WD ? AMP_OK : AMP_E_FEEDBACK);
			if (st.rc == AMP_E_FEEDBACK && !err)
				err = n;
		}
		CHECK_EQ(err, WD);
		/* the servo's records are whole again: AMP_OK from the first */
		st = cycle();	/* reads the last spoilt one */
		CHECK_EQ(st.rc, AMP_E_FEEDBACK);
		st = cycle();
		CHECK_EQ(st.rx.status, AMP_RX_MISSED);	/* the refused ones skipped */
		CHECK_EQ(st.rc, AMP_OK);
		CHECK_EQ(healthy(10), 0);

		/* every other record refused, for a long time: never an error */
		for (n = 0; n < 400; n++) {
			st = (n & 1u) ? cycle() : cycle_spoilt(how);
			CHECK_EQ(st.rc, AMP_OK);
		}
		/* wd_limit - 1 refused, one good, again and again: never an error */
		for (n = 0; n < 400; n++) {
			st = (n % WD == WD - 1u) ? cycle() : cycle_spoilt(how);
			CHECK_EQ(st.rc, AMP_OK);
		}
	}
}

/* Nothing published (a servo that only beats, amp_servo_heartbeat) is
 * not a refused read: STALE for as long as it lasts is no error. */
static void test_stale_beating_is_no_error(void)
{
	struct amp_cmd_axis a[1] = { { 0 } };
	struct amp_rx_info rx;

	start(WD);
	CHECK_EQ(healthy(20), 0);
	for (unsigned n = 0; n < 5u * WD; n++) {
		amp_servo_heartbeat(&S);
		CHECK_EQ(amp_linux_cycle(&L, a, 1, 0, &rx), AMP_OK);
		CHECK_EQ(rx.status, n ? AMP_RX_STALE : AMP_RX_FRESH);
	}
}

int main(void)
{
	test_report_stray_zero_fb_pub();
	test_unseen_reattach_reported();
	test_refused_streak_bounded();
	test_stale_beating_is_no_error();
	test_every_word_every_hostile_value();
	return check_summary("test_amp_resync");
}
