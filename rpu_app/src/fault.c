/* SPDX-License-Identifier: MIT */
/*
 * fault.c - fatal exceptions (undefined instruction, SVC, aborts, FIQ).
 *
 * The report goes to the trace buffer and the UART, the status word
 * becomes "CRSH" (an extension of the stop contract: Linux can see the
 * firmware died instead of waiting for a heartbeat timeout), and the core
 * then keeps honouring the cooperative stop: on STOP it releases its
 * interrupts, stops its timer and parks like a normal stop, so a crashed
 * firmware can be stopped and restarted without a reset.
 * Interrupts acknowledged and not yet completed when the fault came (a
 * fault in a handler, or right after the acknowledge) are completed at
 * once (irq_complete_all): none stays active in the CPU interface, where
 * it would block every interrupt at or below its priority for good, also
 * after a restart.
 */
#include <stdint.h>

#include "arch.h"
#include "board.h"
#include "gic.h"
#include "irq.h"
#include "log.h"
#include "memprot.h"
#include "servo.h"
#include "ttc.h"

static const char *const kind_name[] = {
	"?", "undefined instruction", "SVC", "prefetch abort", "data abort", "FIQ",
};

static volatile uint32_t in_fault;

#define KIND_DATA_ABORT 4u

void fault_report(uint32_t kind, const uint32_t *frame)
{
	uint32_t ids[8], n;

	/* frame: spsr, r0..r12, return address (faulting instruction). */
#if BOARD_HAS_STOP_CONTRACT
	mmio_write32(BOARD_STOP_STATUS_ADDR, ZSR_STATUS_CRASHED);
	dsb();
#endif
	if (!in_fault) {
		in_fault = 1;
		log_printf("FAULT: %s at pc=%08x spsr=%08x mode=%02x nest=%u\n",
			   kind_name[kind < 6u ? kind : 0u], (unsigned)frame[14], (unsigned)frame[0],
			   (unsigned)(frame[0] & 0x1fu), (unsigned)irq_nest_now());
		uint32_t dfar = CP15_READ(0, c6, c0, 0);

		log_printf("FAULT: dfsr=%08x dfar=%08x ifsr=%08x ifar=%08x\n",
			   (unsigned)CP15_READ(0, c5, c0, 0), (unsigned)dfar,
			   (unsigned)CP15_READ(0, c5, c0, 1), (unsigned)CP15_READ(0, c6, c0, 2));
		/* The no-access page below the SVC stack (servo.ld, the platform's memprot). */
		if (kind == KIND_DATA_ABORT && memprot_enabled() && dfar >= memprot_stack_guard_start() &&
		    dfar < memprot_stack_guard_end())
			log_printf("FAULT: SVC stack overflow: access at %08x in the guard page [%08x, %08x) "
				   "below the %u-byte SVC stack\n",
				   (unsigned)dfar, (unsigned)memprot_stack_guard_start(),
				   (unsigned)memprot_stack_guard_end(), (unsigned)svc_stack_size());
		for (unsigned i = 0; i < 13u; i += 4u)
			log_printf("FAULT: r%u..: %08x %08x %08x %08x\n", i,
				   (unsigned)frame[1 + i], (unsigned)(i + 1u < 13u ? frame[2 + i] : 0u),
				   (unsigned)(i + 2u < 13u ? frame[3 + i] : 0u),
				   (unsigned)(i + 3u < 13u ? frame[4 + i] : 0u));
		n = irq_complete_all(ids, sizeof(ids) / sizeof(ids[0]));
		for (uint32_t i = 0; i < n && i < sizeof(ids) / sizeof(ids[0]); i++)
			log_printf("FAULT: completed irq %u (acknowledged, in service at the fault)\n",
				   (unsigned)ids[i]);
#if BOARD_HAS_STOP_CONTRACT
		log_printf("FAULT: waiting for STOP at %p\n", (void *)(uintptr_t)BOARD_STOP_CONTROL_ADDR);
#else
		log_printf("FAULT: halted until the remoteproc driver powers this core down\n");
#endif
		log_flush();
	}
	(void)irq_complete_all(0, 0);	/* a fault in the fault report: once more */
	for (;;) {
#if BOARD_HAS_STOP_CONTRACT
		if (mmio_read32(BOARD_STOP_CONTROL_ADDR) == ZSR_CTRL_STOP) {
			in_fault = 0;
			servo_quiesce_and_park();
		}
#else
		/* nothing to poll: wait for the power-down without spinning
		 * (under -icount a spinning core takes turns from Linux) */
		wfi();
#endif
	}
}
