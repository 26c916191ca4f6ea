/* SPDX-License-Identifier: MIT */
/*
 * params.h - the servo's parameters (servoamp/servo_proto.h): servod holds
 * the authoritative set (sd->pset, words as on the wire), kept in a text
 * file written atomically, loaded into the servo at every attach with one
 * SP_CMD_PARAM_SET_MANY, and served to ampctl ("param list|get|set").
 */
#ifndef SERVOD_PARAMS_H
#define SERVOD_PARAMS_H

#include <stddef.h>
#include <stdint.h>

#include "servoamp/servo_proto.h"

struct servod;

extern const struct sp_param_desc param_desc[SP_P_COUNT];

/* The defaults, then the file (sd->opt.param_path) over them. */
void params_load(struct servod *sd);
/* Loads the whole set into the servo: SE_OK or SE_* with a message. */
int params_restore(struct servod *sd, char *msg, size_t n);
/* The servo may hold other values than servod's set (sending it back after a
 * refused answer or a failed save failed: session.params_resend): sends the
 * set again, at most once a second (supervisor, servo attached). */
void params_resend(struct servod *sd);
/* Parameter id now w, as a telemetry PARAM event (main thread). */
void params_publish(struct servod *sd, uint32_t id, uint32_t w);

#endif
