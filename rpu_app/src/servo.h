/* SPDX-License-Identifier: MIT */
#ifndef RPU_SERVO_H
#define RPU_SERVO_H

#include <stdint.h>

/* Entry from start.S (C environment ready: stacks, .bss cleared). */
__attribute__((noreturn)) void servo_main(void);
/* Fatal exception report (start.S FAULT_ENTRY); waits for STOP. */
__attribute__((noreturn)) void fault_report(uint32_t kind, const uint32_t *frame);

/* Stop path shared by the main loop and the fault handler. */
__attribute__((noreturn)) void servo_quiesce_and_park(void);
__attribute__((noreturn)) void cpu_park(uint32_t park, uint32_t status_addr, uint32_t status);

/* SVC stack (main loop and every interrupt handler, nested): high-water
 * mark in bytes (painted at start, main.c) and size (servo.ld). */
uint32_t svc_stack_used(void);
uint32_t svc_stack_size(void);

/* GIC CPU interface at this start (main.c, gic_drain_own_active): the
 * interrupts an earlier run left active and this start completed, and the
 * running priority left after that (0xff: idle). */
uint32_t start_irq_drained(void);
uint32_t start_irq_busy_prio(void);

#endif
