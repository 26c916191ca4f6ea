/* SPDX-License-Identifier: MIT */
/*
 * start.S - entry, exception vectors and the IRQ entry of rpu_app.
 *
 * Entry contract (docs: rpu_app/README.md): ARM state, SVC mode, IRQ/FIQ
 * masked, Secure, MMU (MPU) off, r0-r3 undefined. The same entry is used
 * for a first start and for every restart after a cooperative stop, so
 * nothing here relies on earlier contents of RAM: .bss is cleared, every
 * stack pointer and VBAR (where there is one) are set again.
 */
	.syntax unified
	.arm

#define MODE_FIQ 0x11
#define MODE_IRQ 0x12
#define MODE_SVC 0x13
#define MODE_ABT 0x17
#define MODE_UND 0x1b

#include "board_config.h"

/* ------------------------------------------------------------------ */
/*
 * Vector table. With a VBAR (the A9) VBAR points here, at the start of the
 * image, never the shared low vectors. Without one (the Cortex-R5) the
 * link script puts it at 0x0, the ATCM, where the core starts (Linux's
 * upstream R5 driver always starts it at the low vectors: docs/
 * boot-flow-zynqmp.md), and the entries jump anywhere (the image may be
 * in DDR): absolute loads of pc from the literal pool that follows.
 */
	.section .vectors, "ax"
	.align 5
	.global _vectors
_vectors:
#if BOARD_CPU_HAS_VBAR
	b	_start			/* reset (not used through VBAR) */
	b	undef_entry
	b	svc_entry
	b	pabt_entry
	b	dabt_entry
	b	.			/* reserved */
	b	irq_entry
	b	fiq_entry
#else
	ldr	pc, =_start
	ldr	pc, =undef_entry
	ldr	pc, =svc_entry
	ldr	pc, =pabt_entry
	ldr	pc, =dabt_entry
	b	.			/* reserved */
	ldr	pc, =irq_entry
	ldr	pc, =fiq_entry
	.ltorg
#endif

/* ------------------------------------------------------------------ */
	.section .text.entry, "ax"
	.global _start
	.type _start, %function
_start:
	cpsid	aif, #MODE_SVC		/* SVC, IRQ/FIQ/async aborts masked */

	/* SCTLR: keep MMU or MPU and caches off (entered off; enabled later
	 * by memprot_init), low vectors (V=0: VBAR on the A9, 0x0 on the R5),
	 * exceptions in ARM state. */
	mrc	p15, 0, r0, c1, c0, 0
	bic	r0, r0, #(1 << 0)	/* M */
	bic	r0, r0, #(1 << 2)	/* C */
	bic	r0, r0, #(1 << 12)	/* I */
	bic	r0, r0, #(1 << 13)	/* V */
	bic	r0, r0, #(1 << 30)	/* TE */
	mcr	p15, 0, r0, c1, c0, 0
	isb

#if BOARD_CPU_HAS_VBAR
	ldr	r0, =_vectors
	mcr	p15, 0, r0, c12, c0, 0	/* VBAR (Secure bank of this core) */
	isb
#endif

	/* One stack per mode. SVC is the main one (IRQ handlers run on it
	 * too, see irq_entry); the others are small. */
	cps	#MODE_UND
	ldr	sp, =__und_stack_top
	cps	#MODE_ABT
	ldr	sp, =__abt_stack_top
	cps	#MODE_IRQ
	ldr	sp, =__irq_stack_top
	cps	#MODE_FIQ
	ldr	sp, =__fiq_stack_top
	cps	#MODE_SVC
	ldr	sp, =__svc_stack_top

	/* Clear .bss: remoteproc zero-fills it on load, a restart from the
	 * park loop does not reload anything, so never rely on it. */
	ldr	r0, =__bss_start
	ldr	r1, =__bss_end
	mov	r2, #0
	mov	r3, #0
1:	cmp	r0, r1
	strdlo	r2, r3, [r0], #8
	blo	1b

	/* Paint the stacks so their high-water marks can be reported. */
	ldr	r0, =__stacks_start
	ldr	r1, =__stacks_end
	ldr	r2, =0x5354434b		/* "KCTS" */
	mov	r3, r2
2:	cmp	r0, r1
	strdlo	r2, r3, [r0], #8
	blo	2b

	/* VFP on before any C (built -mfloat-abi=hard): CP10/CP11 full
	 * access in CPACR, then FPEXC.EN; FPSCR: round to nearest, no traps. */
	mrc	p15, 0, r0, c1, c0, 2
	orr	r0, r0, #(0xf << 20)
	mcr	p15, 0, r0, c1, c0, 2
	isb
	mov	r0, #(1 << 30)
	vmsr	fpexc, r0
	mov	r0, #0
	vmsr	fpscr, r0

	mov	fp, #0
	bl	servo_main
	b	.			/* servo_main never returns */
	.size _start, . - _start

/* ------------------------------------------------------------------ */
/*
 * IRQ entry with nesting.
 *
 * The return state (lr_irq - 4, spsr_irq) is pushed on the SVC stack with
 * SRS and the handler runs in SVC mode, so lr_irq/spsr_irq are free again
 * when irq_dispatch re-enables IRQs: a higher-priority interrupt (the GIC
 * only signals priorities above the running one) can then preempt the
 * handler. Caller-saved registers and lr_svc are saved; the C code saves
 * the rest (AAPCS). The stack is 8-byte aligned for the C call.
 *
 * The VFP's caller-saved state is saved too, on every nesting level: d0-d7
 * and FPSCR (d8-d15 are callee-saved, kept by the C code; the firmware is
 * built for VFPv3-D16, so there is no d16-d31). A handler that preempts
 * float code (the cycle's controller) at any instruction leaves its
 * registers and flags as they were, and runs itself with the default
 * FPSCR (round to nearest, no flags), whatever the code it preempted set.
 * The nesting self-test checks it every statistics interval
 * (fpu_nest_probe, cpu.S).
 */
	.section .text.irq, "ax"
	.global irq_entry
	.type irq_entry, %function
irq_entry:
	sub	lr, lr, #4
	srsdb	sp!, #MODE_SVC		/* push lr_irq, spsr_irq on the SVC stack */
	cps	#MODE_SVC
	push	{r0-r3, r12, lr}
	vpush	{d0-d7}
	vmrs	r2, fpscr
	mov	r0, #0			/* handlers run with the default FPSCR */
	vmsr	fpscr, r0
	and	r1, sp, #4		/* 8-byte align for AAPCS */
	sub	sp, sp, r1
	push	{r1, r2}		/* the alignment, FPSCR */
	bl	irq_dispatch
	pop	{r1, r2}
	add	sp, sp, r1
	vmsr	fpscr, r2
	vpop	{d0-d7}
	pop	{r0-r3, r12, lr}
	rfeia	sp!			/* pc and cpsr from the SVC stack */
	.size irq_entry, . - irq_entry

/*
 * Synchronous exceptions and FIQ: all fatal for this firmware. Build a
 * frame {r0-r12, lr(exception), spsr} on the mode's stack and call
 * fault_report(kind, frame), which never returns (it waits for STOP).
 */
.macro FAULT_ENTRY name, kind, adjust
	.global \name
	.type \name, %function
\name:
	sub	lr, lr, #\adjust
	push	{r0-r12, lr}
	mrs	r0, spsr
	push	{r0}
	mov	r1, sp
	mov	r0, #\kind
	bic	sp, sp, #7
	bl	fault_report
	b	.
	.size \name, . - \name
.endm

	FAULT_ENTRY undef_entry, 1, 4
	FAULT_ENTRY svc_entry, 2, 0
	FAULT_ENTRY pabt_entry, 3, 4
	FAULT_ENTRY dabt_entry, 4, 8
	FAULT_ENTRY fiq_entry, 5, 4
