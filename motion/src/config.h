/* SPDX-License-Identifier: MIT */
/* Range checks of struct motion_config (motion_create() runs them). */
#ifndef SERVOAMP_MOTION_CONFIG_H
#define SERVOAMP_MOTION_CONFIG_H

#include "motion/motion.h"

/* 0, or -1 with *err (if not NULL) saying which field is wrong. */
int config_check(const struct motion_config *c, struct motion_error *err);

#endif
