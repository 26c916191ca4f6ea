/* SPDX-License-Identifier: MIT */
/*
 * park.S - the last step of the Zynq-7000's cooperative stop: caches
 * cleaned, MMU off, PRKD, back to the boot stub's park loop in OCM.
 *
 * In assembly: no stack use between turning the D-cache off and the
 * clean/invalidate (dcache_setway_regs, src/cpu.S), none after the MMU is
 * off except the status-word store.
 */
	.syntax unified
	.arm
	.section .text.cpu, "ax"

/*
 * cpu_park(park_addr, status_addr, status_value): never returns.
 * IRQ/FIQ masked, SVC mode; D-cache off, then clean+invalidate it (the
 * order ARM recommends, so no line can be allocated after the clean),
 * MMU/I-cache/branch prediction off, TLB/I-cache/BTB invalidated; then
 * the status word is written and the core branches to the park loop,
 * which waits (wfe) for the boot register to hold a new entry.
 * The caller has stopped every interrupt source of the firmware.
 */
	.global cpu_park
	.type cpu_park, %function
cpu_park:
	cpsid	aif, #0x13
	mov	r4, r0
	mov	r5, r1
	mov	r6, r2
	mrc	p15, 0, r0, c1, c0, 0
	bic	r0, r0, #(1 << 2)	/* C off */
	mcr	p15, 0, r0, c1, c0, 0
	isb
	mov	r0, #1
	bl	dcache_setway_regs	/* clean+invalidate, no stack */
	mrc	p15, 0, r0, c1, c0, 0
	bic	r0, r0, #(1 << 0)	/* M */
	bic	r0, r0, #(1 << 11)	/* Z */
	bic	r0, r0, #(1 << 12)	/* I */
	mcr	p15, 0, r0, c1, c0, 0
	isb
	mov	r0, #0
	mcr	p15, 0, r0, c7, c5, 0	/* ICIALLU */
	mcr	p15, 0, r0, c7, c5, 6	/* BPIALL */
	mcr	p15, 0, r0, c8, c7, 0	/* TLBIALL */
	dsb
	isb
	str	r6, [r5]		/* status word: "PRKD" */
	dsb
	bx	r4			/* park loop (ARM code in OCM) */
	.size cpu_park, . - cpu_park
