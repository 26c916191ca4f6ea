/* SPDX-License-Identifier: MIT */
/*
 * zynq7000_qemu boot stub, placed at the start of OCM (0xfffc0000, 4 KiB).
 *
 * QEMU models no boot ROM and no FSBL, and its `-kernel` path cannot boot
 * this two-core machine. The launcher loads the images with
 * `-device loader` and points BOTH CPUs at _start:
 *
 *  CPU0 does what FSBL/U-Boot would do: unlock the SLCR, program
 *       ARM_PLL_CTRL (so that Linux computes the 100 MHz CPU_3x2x clock QEMU
 *       runs its A9 timers at), lock the SLCR again, and enter the zImage
 *       with r0 = 0, r1 = ~0 (no machine number: devicetree boot),
 *       r2 = DTB address.
 *  CPU1 does what the Zynq-7000 boot ROM does: wait in the park loop at
 *       the FIXED address _start + PARK_OFFSET (0xfffc0100) until the
 *       boot register 0xfffffff0 is not zero, then branch to it. The
 *       servoamp remoteproc driver starts CPU1 by writing the firmware
 *       entry there, dsb, sev; a firmware returns here on a stop request.
 *
 * Build-time parameters (from board.yaml, see Makefile): ZIMAGE_ADDR,
 * DTB_ADDR, ARM_PLL_CTRL_VALUE, PARK_OFFSET; PARK_WFE (default 1).
 *
 * PARK_WFE=1: the park loop waits in wfe between polls, as the boot ROM
 * does (with guest time on the host clock, a parked CPU1 costs no host
 * time). PARK_WFE=0: it polls without wfe. Under -icount QEMU's wfe only
 * yields to the other vCPU, so a parked CPU1 never lets virtual time warp
 * to the next timer event and the guest crawls (`sleep 1` took 40 s);
 * plain polling advances virtual time with every instruction instead.
 */
#ifndef PARK_WFE
#define PARK_WFE 1
#endif
#ifndef ZIMAGE_ADDR
#error "ZIMAGE_ADDR not set"
#endif
#ifndef DTB_ADDR
#error "DTB_ADDR not set"
#endif
#ifndef ARM_PLL_CTRL_VALUE
#error "ARM_PLL_CTRL_VALUE not set"
#endif
#ifndef PARK_OFFSET
#error "PARK_OFFSET not set"
#endif

#define SLCR_BASE		0xf8000000
#define SLCR_LOCK		0x004
#define SLCR_UNLOCK		0x008
#define SLCR_ARM_PLL_CTRL	0x100
#define SLCR_LOCK_KEY		0x767b
#define SLCR_UNLOCK_KEY		0xdf0d

	.syntax unified
	.arm
	.section .text.stub, "ax"
	.global _start
_start:
	mrc	p15, 0, r4, c0, c0, 5		@ MPIDR
	ands	r4, r4, #3			@ CPU number
	bne	park

	/* CPU0: clocks as FSBL leaves them, then Linux */
	movw	r4, #:lower16:SLCR_BASE
	movt	r4, #:upper16:SLCR_BASE
	movw	r5, #SLCR_UNLOCK_KEY
	str	r5, [r4, #SLCR_UNLOCK]
	movw	r5, #:lower16:ARM_PLL_CTRL_VALUE
	movt	r5, #:upper16:ARM_PLL_CTRL_VALUE
	str	r5, [r4, #SLCR_ARM_PLL_CTRL]
	movw	r5, #SLCR_LOCK_KEY
	str	r5, [r4, #SLCR_LOCK]
	dsb
	mov	r0, #0
	mvn	r1, #0
	movw	r2, #:lower16:DTB_ADDR
	movt	r2, #:upper16:DTB_ADDR
	movw	r3, #:lower16:ZIMAGE_ADDR
	movt	r3, #:upper16:ZIMAGE_ADDR
	bx	r3

	/* CPU1: the boot ROM's wait loop, at a fixed address */
	.org	PARK_OFFSET
	.global park
park:
#if PARK_WFE
	wfe
#endif
	mvn	r3, #0xf			@ r3 = 0xfffffff0, the boot register
	ldr	r3, [r3]
	cmp	r3, #0
	beq	park
	bx	r3
