/* SPDX-License-Identifier: MIT */
#ifndef RPU_LINK_H
#define RPU_LINK_H

#include <stdint.h>

/*
 * The firmware's only interface to the OCM transport (amp_lib). Built
 * with amp_lib's servo side when HAVE_AMP_LIB=1 (the Makefile's default
 * when amp_lib/src/amp_servo.c exists), else with a local heartbeat
 * counter that never touches OCM.
 */
void link_init(void);
/* Main loop: attach / retry every BOARD_ATTACH_RETRY_CYCLES cycles. */
void link_poll(uint32_t cycle);
/* Cycle interrupt: heartbeat (once per cycle). */
void link_cycle(void);
int link_attached(void);
uint32_t link_heartbeat(void);
const char *link_backend(void);

#endif
