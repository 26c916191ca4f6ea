/* SPDX-License-Identifier: MIT */
/*
 * qemu_stub.S - OCM image for running rpu_app in QEMU WITHOUT Linux
 * (tests/rpu_app). Not part of the firmware.
 *
 *  BOARD_PARK_ADDR  the CPU1 park loop of the board contract, identical
 *                   in behaviour to the board's boot stub: wfe; poll the
 *                   boot register; bx to a non-zero entry. The firmware
 *                   branches here on a cooperative stop.
 *  OCM + 0x800      CPU0: stands in for Linux only where the firmware
 *                   depends on it: enables the GIC distributor (GICD_CTLR,
 *                   which the firmware never writes) and starts the global
 *                   timer like Linux's clocksource (prescaler 1), then
 *                   starts CPU1 the way the remoteproc driver does: the
 *                   firmware entry (a word the test's QEMU loader puts at
 *                   STUB_FW_ENTRY) into the boot register, dsb, sev; then
 *                   sleeps in WFI with its CPU interface disabled.
 * CPU1 starts in the park loop, so the firmware never runs before CPU0 has
 * set up what it depends on (it reads the global timer's prescaler once).
 */
#include "board_config.h"

/* outside the stub image, so the ROM copy of the stub never overwrites it */
#define STUB_FW_ENTRY (BOARD_OCM_BASE + 0xf00)
	.global	stub_fw_entry
	.set	stub_fw_entry, STUB_FW_ENTRY

	.syntax unified
	.arm
	.section .stub, "ax"

	.org	BOARD_PARK_ADDR - BOARD_OCM_BASE
	.global park_loop
park_loop:
	wfe
	movw	r2, #:lower16:BOARD_BOOT_REG_ADDR
	movt	r2, #:upper16:BOARD_BOOT_REG_ADDR
	ldr	r3, [r2]
	cmp	r3, #0
	beq	park_loop
	bx	r3

	.org	0x800
	.global cpu0_main
cpu0_main:
	cpsid	aif
	movw	r0, #:lower16:BOARD_GICD_BASE
	movt	r0, #:upper16:BOARD_GICD_BASE
	mov	r1, #1
	str	r1, [r0]			/* GICD_CTLR = 1 (Linux's job) */
	movw	r0, #:lower16:BOARD_GTIMER_BASE
	movt	r0, #:upper16:BOARD_GTIMER_BASE
	mov	r1, #0
	str	r1, [r0, #8]			/* stop */
	str	r1, [r0, #0]
	str	r1, [r0, #4]			/* counter = 0 */
	movw	r1, #0x101
	str	r1, [r0, #8]			/* enable, prescaler 1 (as Linux 6.1 does) */
	movw	r1, #:lower16:STUB_FW_ENTRY
	movt	r1, #:upper16:STUB_FW_ENTRY
	ldr	r1, [r1]
	movw	r0, #:lower16:BOARD_BOOT_REG_ADDR
	movt	r0, #:upper16:BOARD_BOOT_REG_ADDR
	str	r1, [r0]			/* 0 keeps CPU1 parked */
	dsb
	sev
1:	wfi
	b	1b
