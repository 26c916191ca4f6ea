/* SPDX-License-Identifier: MIT */
#ifndef RPU_CAN_FRAME_H
#define RPU_CAN_FRAME_H

#include <stdint.h>

/* One classic CAN frame with a standard 11-bit identifier: what the CANPS
 * driver (canps.c) receives and sends and the CANopen master
 * (canopen_master.c) consumes and produces. */
struct can_frame {
	uint32_t id;		/* 11-bit identifier (COB-ID) */
	uint8_t dlc;		/* 0..8 */
	uint8_t rtr;		/* remote frame */
	uint8_t data[8];
};

#endif
