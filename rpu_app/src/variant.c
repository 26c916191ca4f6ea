/* SPDX-License-Identifier: MIT */
/*
 * variant.c - what differs between servo.elf and servo-norsc.elf: the
 * remoteproc resource table (Linux include/linux/remoteproc.h, version 1)
 * with one RSC_TRACE entry describing trace_buf (log.c). Built twice:
 * RPU_RSC=1 (servo.elf) and RPU_RSC=0 (servo-norsc.elf, no
 * .resource_table section at all: valid firmware for a remoteproc driver
 * that accepts a table-less ELF, and for loaders other than remoteproc).
 */
#include <stddef.h>
#include <stdint.h>

#include "board.h"
#include "log.h"
#include "variant.h"

#ifndef RPU_RSC
#error "RPU_RSC must be 0 or 1"
#endif

#if RPU_RSC
#define RSC_TRACE 2u

struct fw_rsc_trace {
	uint32_t type;		/* struct fw_rsc_hdr */
	uint32_t da;
	uint32_t len;
	uint32_t reserved;
	uint8_t name[32];
};

struct servo_rsc_table {
	uint32_t ver;
	uint32_t num;
	uint32_t reserved[2];
	uint32_t offset[1];
	struct fw_rsc_trace trace;
};

__attribute__((section(".resource_table"), used, aligned(8)))
const struct servo_rsc_table servo_rsc_table = {
	.ver = 1,
	.num = 1,
	.offset = { offsetof(struct servo_rsc_table, trace) },
	.trace = {
		.type = RSC_TRACE,
		.da = (uint32_t)(uintptr_t)trace_buf,
		.len = BOARD_TRACE_SIZE,
		.name = "servo_trace",
	},
};

const char rpu_variant[] = "servo (resource table: trace)";
const int rpu_has_rsc = 1;
#else
const char rpu_variant[] = "servo-norsc (no resource table)";
const int rpu_has_rsc = 0;
#endif
