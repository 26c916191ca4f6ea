/* SPDX-License-Identifier: MIT */
/*
 * cpu.S - ARMv7 cache maintenance by set/way (both platforms) and the
 * nesting self-test's VFP probe.
 *
 * Written in assembly because the cache maintenance must not touch memory
 * through the data cache while it is being switched (platform/zynq7000_a9/
 * park.S runs dcache_setway_regs with the D-cache already off).
 */
	.syntax unified
	.arm

/* FPSCR for fpu_nest_probe: RMode 0b11 (towards zero), IOC and DZC set */
#define FPSCR_PATTERN 0x00c00003
	.section .text.cpu, "ax"

/*
 * dcache_setway(op): op 0 = invalidate (DCISW), 1 = clean+invalidate
 * (DCCISW), every data/unified cache level up to the Level of Coherency
 * (CLIDR). On the A9 this is L1 only: the PL310 L2 is an outer cache
 * owned by Linux and is never maintained (or used) by the firmware, whose
 * cacheable memory is marked outer non-cacheable (see mmu.c).
 *
 * dcache_setway_regs is the same loop without any memory access (no
 * stack): it uses r0-r3 and r7-r12 and keeps r4-r6, sp and lr, so that
 * cpu_park (platform/zynq7000_a9/park.S) can run it with the D-cache already off (a push there could be
 * overwritten by the write-back of a stale dirty line of the stack).
 */
	.global dcache_setway
	.type dcache_setway, %function
dcache_setway:
	push	{r4-r11, lr}
	bl	dcache_setway_regs
	pop	{r4-r11, pc}
	.size dcache_setway, . - dcache_setway

	.global dcache_setway_regs
	.type dcache_setway_regs, %function
dcache_setway_regs:
	mov	r11, r0			/* op */
	mrc	p15, 1, r0, c0, c0, 1	/* CLIDR */
	ands	r3, r0, #0x07000000	/* LoC */
	mov	r3, r3, lsr #23		/* LoC * 2 */
	beq	5f
	mov	r10, #0			/* level * 2 */
1:	add	r2, r10, r10, lsr #1	/* level * 3 */
	mov	r1, r0, lsr r2
	and	r1, r1, #7		/* cache type at this level */
	cmp	r1, #2
	blt	4f			/* no data cache */
	mcr	p15, 2, r10, c0, c0, 0	/* CSSELR */
	isb
	mrc	p15, 1, r1, c0, c0, 0	/* CCSIDR */
	and	r2, r1, #7
	add	r2, r2, #4		/* log2(line bytes) */
	movw	r8, #0x3ff
	ands	r8, r8, r1, lsr #3	/* ways - 1 */
	clz	r12, r8			/* way shift */
	movw	r7, #0x7fff
	ands	r7, r7, r1, lsr #13	/* sets - 1 */
2:	mov	r9, r8			/* way */
3:	orr	r1, r10, r9, lsl r12
	orr	r1, r1, r7, lsl r2
	cmp	r11, #0
	mcreq	p15, 0, r1, c7, c6, 2	/* DCISW */
	mcrne	p15, 0, r1, c7, c14, 2	/* DCCISW */
	subs	r9, r9, #1
	bge	3b
	subs	r7, r7, #1
	bge	2b
4:	add	r10, r10, #2
	cmp	r3, r10
	bgt	1b
5:	mov	r10, #0
	mcr	p15, 2, r10, c0, c0, 0	/* CSSELR back to L1 */
	dsb
	isb
	bx	lr
	.size dcache_setway_regs, . - dcache_setway_regs

/*
 * fpu_nest_probe(sgir, word, seen): the nesting self-test's VFP half.
 * r0 = the GIC's SGI register, r1 = the word that sends the test SGI to
 * this core, r2 = the SGI handler's counter. Called from the cycle
 * handler: fills d0-d7 and FPSCR (round towards zero, IOC and DZC set)
 * with patterns, raises the SGI, whose handler (higher priority: it
 * preempts at once) computes with the VFP, waits until the counter
 * moves, then checks that every register came back. Returns 0: all
 * back; 1..8: d0..d7 changed (the first one + 1); 9: FPSCR changed;
 * 10: the SGI never came. In assembly, so that no call or spill stands
 * between the patterns and the check. FPSCR is 0 again on return.
 */
	.global fpu_nest_probe
	.type fpu_nest_probe, %function
fpu_nest_probe:
	push	{r4-r8, lr}
	ldr	r4, [r2]		/* the counter before */
	ldr	r8, =0x01010101
	mov	r5, #0
	.irp	i, 0, 1, 2, 3, 4, 5, 6, 7
	add	r5, r5, r8
	mvn	r6, r5
	vmov	d\i, r5, r6
	.endr
	ldr	r3, =FPSCR_PATTERN
	vmsr	fpscr, r3
	dsb
	str	r1, [r0]		/* the SGI */
	dsb
	ldr	r7, =0x10000
1:	ldr	r3, [r2]
	cmp	r3, r4
	bne	2f
	subs	r7, r7, #1
	bne	1b
	mov	r0, #10
	b	9f
2:	mov	r5, #0
	.irp	i, 0, 1, 2, 3, 4, 5, 6, 7
	add	r5, r5, r8
	mvn	r6, r5
	vmov	r3, r12, d\i
	cmp	r3, r5
	cmpeq	r12, r6
	movne	r0, #(\i + 1)
	bne	9f
	.endr
	vmrs	r3, fpscr
	ldr	r12, =FPSCR_PATTERN
	cmp	r3, r12
	movne	r0, #9
	bne	9f
	mov	r0, #0
9:	mov	r3, #0
	vmsr	fpscr, r3
	pop	{r4-r8, pc}
	.size fpu_nest_probe, . - fpu_nest_probe
	.ltorg
