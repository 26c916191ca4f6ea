/* SPDX-License-Identifier: MIT */
/*
 * mailbox.h - requests to the servo through amp_lib's mailbox, from the
 * main thread: posted and polled under sd->lock (the cycle thread keeps
 * its cycle meanwhile), given up after MBOX_TIMEOUT_MS.
 */
#ifndef SERVOD_MAILBOX_H
#define SERVOD_MAILBOX_H

#include <stddef.h>
#include <stdint.h>

#include "servoamp/servo_proto.h"

#define MBOX_TIMEOUT_MS 200

struct servod;

/* SE_OK and the servo's status in *status (answer in resp, *rlen bytes),
 * or SE_OFFLINE / SE_TIMEOUT / SE_VALUE / SE_SERVO with a message. */
int mbox_request(struct servod *sd, uint32_t command, const void *req, uint32_t len, void *resp,
		 uint32_t cap, uint32_t *rlen, int32_t *status, char *msg, size_t n);
/* The servo's SP_E_* status as text. */
const char *sp_strerror(int32_t s);
/* SP_CMD_STATUS: SE_OK and *s, or SE_* with a message. */
int servo_status(struct servod *sd, struct sp_status *s, char *msg, size_t n);

#endif
