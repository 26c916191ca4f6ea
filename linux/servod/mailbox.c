// SPDX-License-Identifier: MIT
/* mailbox.c - requests to the servo; the "raw", "resume" and "debug"
 * requests (mailbox.h). */
#define _GNU_SOURCE
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "context.h"

int mbox_request(struct servod *sd, uint32_t command, const void *req, uint32_t len, void *resp,
		 uint32_t cap, uint32_t *rlen, int32_t *status, char *msg, size_t n)
{
	struct amp_msg q = { command, 0, len, len, (void *)req };
	struct amp_msg r = { 0, 0, 0, cap, resp };
	const uint64_t limit = MBOX_TIMEOUT_MS * 1000000ull;
	uint64_t t0 = mono_now_ns();
	int rc;

	/* the servo may still hold the token of an earlier request it did
	 * not answer in time: wait (within the same timeout) for it */
	for (;;) {
		pthread_mutex_lock(&sd->lock);
		rc = session_open(&sd->session) ? amp_linux_mbox_post(&sd->amp, &q) : AMP_E_PEER_ABSENT;
		pthread_mutex_unlock(&sd->lock);
		if (rc != AMP_E_BUSY || mono_now_ns() - t0 > limit)
			break;
		usleep(200);
	}
	if (rc == AMP_OK) {
		do {
			usleep(200);
			pthread_mutex_lock(&sd->lock);
			rc = amp_linux_mbox_poll(&sd->amp, &r);
			if (rc == AMP_E_BUSY && mono_now_ns() - t0 > limit) {
				(void)amp_linux_mbox_cancel(&sd->amp);
				rc = AMP_E_TIMEOUT;
			}
			pthread_mutex_unlock(&sd->lock);
		} while (rc == AMP_E_BUSY);
	}
	switch (rc) {
	case AMP_OK:
		*status = r.status;
		if (rlen)
			*rlen = r.length;
		return SE_OK;
	case AMP_E_PEER_ABSENT:
		snprintf(msg, n, "servo not running (remoteproc %s, not attached to servod's region)",
			 rproc_state(&sd->rproc));
		return SE_OFFLINE;
	case AMP_E_PEER_STOPPING:
		snprintf(msg, n, "servo not running (stopping on request, remoteproc %s)", rproc_state(&sd->rproc));
		return SE_OFFLINE;
	case AMP_E_TIMEOUT:
	case AMP_E_BUSY:
		snprintf(msg, n, "servo did not answer within %d ms (%s)", MBOX_TIMEOUT_MS, amp_strerror(rc));
		return SE_TIMEOUT;
	default:
		snprintf(msg, n, "mailbox: %s (%d)", amp_strerror(rc), rc);
		return rc == AMP_E_NOSPC ? SE_VALUE : SE_SERVO;
	}
}

const char *sp_strerror(int32_t s)
{
	switch (s) {
	case SP_OK: return "ok";
	case SP_E_CMD: return "unknown command (SP_E_CMD)";
	case SP_E_LENGTH: return "bad payload length (SP_E_LENGTH)";
	case SP_E_ID: return "unknown parameter id (SP_E_ID)";
	case SP_E_RANGE: return "value out of range (SP_E_RANGE)";
	case SP_E_READONLY: return "read-only parameter (SP_E_READONLY)";
	case SP_E_STATE: return "not possible in this state (SP_E_STATE)";
	case SP_E_OVERLOAD:
		return "period too short for the servo's measured handler cost, nothing changed (SP_E_OVERLOAD)";
	default: return amp_strerror(s);
	}
}

int servo_status(struct servod *sd, struct sp_status *s, char *msg, size_t n)
{
	uint32_t len = 0;
	int32_t status;
	int rc = mbox_request(sd, SP_CMD_STATUS, 0, 0, s, sizeof(*s), &len, &status, msg, n);

	if (rc)
		return rc;
	if (status) {
		snprintf(msg, n, "status: %s", sp_strerror(status));
		return SE_SERVO;
	}
	/* a firmware of another protocol revision (or a garbled answer) */
	if (len != sizeof(*s)) {
		snprintf(msg, n, "status: answer of %u bytes, expected %zu (firmware and servod differ?)", len,
			 sizeof(*s));
		return SE_SERVO;
	}
	if (s->svc_stack_used > s->svc_stack_size) {
		snprintf(msg, n, "status: svc_stack_used %u over svc_stack_size %u", s->svc_stack_used,
			 s->svc_stack_size);
		return SE_SERVO;
	}
	return SE_OK;
}

/* "raw COMMAND NBYTES [WORD...]": any mailbox command, the answer's first words. */
static int req_raw(struct servod *sd, struct out *o, int argc, char **argv, char *msg, size_t n)
{
	uint32_t req[(AMP_MBOX_CAPACITY + 64) / 4], resp[AMP_MBOX_CAPACITY / 4];
	uint32_t cmd, len, rlen = 0;
	int32_t status;
	int rc;

	argc--, argv++;
	if (argc < 2) {
		snprintf(msg, n, "usage: raw COMMAND NBYTES [WORD...]");
		return SE_USAGE;
	}
	cmd = (uint32_t)strtoul(argv[0], 0, 0);
	len = (uint32_t)strtoul(argv[1], 0, 0);
	if (len > sizeof(req)) {
		snprintf(msg, n, "raw: at most %zu bytes", sizeof(req));
		return SE_USAGE;
	}
	memset(req, 0, sizeof(req));
	for (int i = 2; i < argc && (uint32_t)(i - 2) < len / 4u; i++)
		req[i - 2] = (uint32_t)strtoul(argv[i], 0, 0);
	rc = mbox_request(sd, cmd, req, len, resp, sizeof(resp), &rlen, &status, msg, n);
	if (rc)
		return rc;
	put(o, "status=%d (%s) length=%u\n", status, sp_strerror(status), rlen);
	for (uint32_t i = 0; i < rlen / 4u && i < 16u; i++)
		put(o, "word[%u]=0x%08x\n", i, resp[i]);
	return SE_OK;
}
SERVOD_REQUEST("raw", req_raw);

/* A command without an answer payload: "NAME: ok" or the servo's status. */
static int simple_command(struct servod *sd, struct out *o, const char *name, uint32_t cmd, uint32_t w,
			  uint32_t len, char *msg, size_t n)
{
	int32_t status;
	int rc = mbox_request(sd, cmd, &w, len, 0, 0, 0, &status, msg, n);

	if (!rc && status) {
		snprintf(msg, n, "%s: %s", name, sp_strerror(status));
		rc = SE_SERVO;
	} else if (!rc) {
		put(o, "%s: ok\n", name);
	}
	return rc;
}

/* "resume": the servo leaves its safe stop and acknowledges the drives' faults. */
static int req_resume(struct servod *sd, struct out *o, int argc, char **argv, char *msg, size_t n)
{
	(void)argc;
	return simple_command(sd, o, argv[0], SP_CMD_RESUME, 0, 0, msg, n);
}
SERVOD_REQUEST("resume", req_resume);

/* "debug hang|crash|fault|badparam|stack|overload|stray-irq|irq-abort|slow US": the
 * servo hangs, crashes, faults and hangs, gives one out-of-range parameter
 * answer, overflows its SVC stack into the guard page (a crash), runs its
 * cycle handlers back to back, gets a stray level interrupt, faults right
 * after acknowledging a cycle interrupt (a crash with it active), or takes US
 * microseconds longer per cycle handler, on purpose (tests). */
static int req_debug(struct servod *sd, struct out *o, int argc, char **argv, char *msg, size_t n)
{
	uint32_t w;

	if (argc == 3 && !strcmp(argv[1], "slow")) {
		uint32_t req[2] = { SP_DEBUG_SLOW, 0 };
		char *end;
		unsigned long us = strtoul(argv[2], &end, 10);
		int32_t status;
		int rc;

		if (!*argv[2] || *end || us > 10000ul) {
			snprintf(msg, n, "debug slow: microseconds 0..10000 expected");
			return SE_USAGE;
		}
		req[1] = (uint32_t)us;
		rc = mbox_request(sd, SP_CMD_DEBUG, req, sizeof(req), 0, 0, 0, &status, msg, n);
		if (!rc && status) {
			snprintf(msg, n, "%s: %s", argv[0], sp_strerror(status));
			rc = SE_SERVO;
		} else if (!rc) {
			put(o, "%s: ok\n", argv[0]);
		}
		return rc;
	}

	if (argc == 2 && !strcmp(argv[1], "hang"))
		w = SP_DEBUG_HANG;
	else if (argc == 2 && !strcmp(argv[1], "crash"))
		w = SP_DEBUG_CRASH;
	else if (argc == 2 && !strcmp(argv[1], "fault"))
		w = SP_DEBUG_FAULT;
	else if (argc == 2 && !strcmp(argv[1], "badparam"))
		w = SP_DEBUG_BADPARAM;
	else if (argc == 2 && !strcmp(argv[1], "stack"))
		w = SP_DEBUG_STACK;
	else if (argc == 2 && !strcmp(argv[1], "overload"))
		w = SP_DEBUG_OVERLOAD;
	else if (argc == 2 && !strcmp(argv[1], "stray-irq"))
		w = SP_DEBUG_STRAY_IRQ;
	else if (argc == 2 && !strcmp(argv[1], "irq-abort"))
		w = SP_DEBUG_IRQ_ABORT;
	else {
		snprintf(msg, n, "usage: debug hang|crash|fault|badparam|stack|overload|stray-irq|irq-abort|slow US");
		return SE_USAGE;
	}
	return simple_command(sd, o, argv[0], SP_CMD_DEBUG, w, 4, msg, n);
}
SERVOD_REQUEST("debug", req_debug);
