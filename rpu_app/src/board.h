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

/* amp_lib bare-metal port hook: rate of amp_board_ticks() (the platform time base, timebase.h). */
#define AMP_BOARD_TICKS_PER_US BOARD_TIMEBASE_TICKS_PER_US
uint32_t amp_board_ticks(void);

/* The driver's control word and our status word: STOP, RUN!, PRKD, CRSH. */
#include "servoamp/rproc_words.h"

#endif
