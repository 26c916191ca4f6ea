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
 * time). PARK_WFE=0 (virtual time, -icount): it waits in wfi and wakes on
 * CPU1's own private timer every PARK_TICK_US. Under -icount QEMU's wfe
 * only yields to the other vCPU, so a CPU1 parked in wfe never lets virtual
 * time warp to the next timer event (`sleep 1` took 40 s); a CPU1 that
 * polls without waiting is never idle either, and every broadcast TLB
 * maintenance operation of Linux on CPU0 then costs a whole round-robin
 * time slice of CPU1's polling (a vmap purge of ~100k pages took 21 s of
 * guest time). A halted CPU1 costs neither. The timer and its interrupt
 * are switched off again before the branch to a firmware.
 */
#ifndef PARK_WFE
#define PARK_WFE 1
#endif
#ifndef PARK_TICK_US
#define PARK_TICK_US 200
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

/* A9 MPCore private peripherals (banked per CPU where noted) */
#define GICC_BASE		0xf8f00100	/* CPU interface (banked) */
#define GICC_CTLR		0x00
#define GICC_PMR		0x04
#define GICC_IAR		0x0c
#define GICC_EOIR		0x10
#define TWD_BASE		0xf8f00600	/* private timer (banked) */
#define TWD_LOAD		0x00
#define TWD_CTRL		0x08
#define TWD_ISR			0x0c
#define TWD_CTRL_RUN		0x7		/* enable, auto-reload, IRQ */
#define TWD_HZ			100000000	/* QEMU's PERIPHCLK (CPU_3x2x) */
#define GICD_ISENABLER0		0xf8f01100	/* SGI/PPI enables (banked) */
#define GICD_ICENABLER0		0xf8f01180
#define TWD_PPI			29

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
	mvn	r3, #0xf			@ r3 = 0xfffffff0, the boot register
	ldr	r3, [r3]
	cmp	r3, #0
	beq	park
	bx	r3
#else
	/* interrupts stay masked (CPSR.I): wfi still wakes on a pending one */
	movw	r4, #:lower16:GICC_BASE
	movt	r4, #:upper16:GICC_BASE
	mov	r5, #0xf0
	str	r5, [r4, #GICC_PMR]
	mov	r5, #1
	str	r5, [r4, #GICC_CTLR]
	movw	r6, #:lower16:TWD_BASE
	movt	r6, #:upper16:TWD_BASE
	mov	r5, #0
	str	r5, [r6, #TWD_CTRL]
	movw	r5, #:lower16:(TWD_HZ / 1000000 * PARK_TICK_US - 1)
	movt	r5, #:upper16:(TWD_HZ / 1000000 * PARK_TICK_US - 1)
	str	r5, [r6, #TWD_LOAD]
	mov	r5, #1
	str	r5, [r6, #TWD_ISR]
	movw	r7, #:lower16:GICD_ISENABLER0
	movt	r7, #:upper16:GICD_ISENABLER0
	mov	r5, #(1 << TWD_PPI)
	str	r5, [r7]
	mov	r5, #TWD_CTRL_RUN
	str	r5, [r6, #TWD_CTRL]
	dsb
1:	mvn	r3, #0xf			@ r3 = 0xfffffff0, the boot register
	ldr	r3, [r3]
	cmp	r3, #0
	bne	2f
	wfi
	ldr	r5, [r4, #GICC_IAR]		@ acknowledge whatever woke us
	mov	r8, #1
	str	r8, [r6, #TWD_ISR]
	ubfx	r8, r5, #0, #10
	movw	r9, #1023
	cmp	r8, r9
	strne	r5, [r4, #GICC_EOIR]
	b	1b
2:	mov	r5, #0				@ leave no timer behind for the firmware
	str	r5, [r6, #TWD_CTRL]
	mov	r5, #1
	str	r5, [r6, #TWD_ISR]
	mov	r5, #(1 << TWD_PPI)
	str	r5, [r7, #GICD_ICENABLER0 - GICD_ISENABLER0]
	dsb
	bx	r3
#endif
