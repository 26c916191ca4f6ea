/* SPDX-License-Identifier: MIT */
/*
 * board.h - the generated board configuration (build/rpu_app/<board>/
 * board_config.h, from boards/<board>/servo.dts) plus what the amp_lib
 * bare-metal port needs from the board. Also force-included when amp_lib
 * sources are compiled into the firmware.
 */
#ifndef RPU_BOARD_H
#define RPU_BOARD_H

#include <stdint.h>

#include "board_config.h"

/* amp_lib bare-metal port hook: rate of amp_board_ticks() (gtimer.c). */
#define AMP_BOARD_TICKS_PER_US BOARD_GTIMER_TICKS_PER_US
uint32_t amp_board_ticks(void);

/* Stop protocol words (board contract). */
#define STOP_CTRL_RUN   0x00000000u
#define STOP_CTRL_STOP  0x53544f50u	/* "STOP" */
#define STOP_STAT_RUN   0x52554e21u	/* "RUN!" */
#define STOP_STAT_PRKD  0x50524b44u	/* "PRKD" */
#define STOP_STAT_CRSH  0x48535243u	/* "CRSH": firmware fault (extension) */

#endif
