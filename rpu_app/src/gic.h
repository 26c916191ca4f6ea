/* SPDX-License-Identifier: MIT */
#ifndef RPU_GIC_H
#define RPU_GIC_H

#include <stdint.h>

#define GIC_SPURIOUS 1023u

/*
 * GIC (v1, Cortex-A9 MPCore) access limited to what this core owns: its
 * own CPU interface (banked) and the per-interrupt registers of the
 * interrupts it registered. GICD_CTLR belongs to Linux: it is only read.
 */
int gic_dist_enabled(void);
void gic_cpu_init(uint32_t pmr, uint32_t bpr);
void gic_cpu_disable(void);
/* Configure one owned interrupt (disabled on return). */
void gic_irq_config(uint32_t id, uint32_t prio, int level);
void gic_irq_enable(uint32_t id);
void gic_irq_disable(uint32_t id);	/* also clears its pending state */
void gic_irq_pend(uint32_t id);		/* set its pending state (ISPENDR) */
uint32_t gic_ack(void);
void gic_eoi(uint32_t iar);
uint32_t gic_running_priority(void);
void gic_sgi_self(uint32_t id);

#endif
