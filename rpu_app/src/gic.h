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
void gic_dist_enable(void);	/* only for a GIC of this core's own */
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
/* The SGI register and the word that sends SGI id to this core only (for
 * code that must raise one without a call: fpu_nest_probe). */
volatile uint32_t *gic_sgir(void);
uint32_t gic_sgi_self_word(uint32_t id);

/*
 * Start: complete the interrupts an earlier run of the firmware left active
 * in this core's CPU interface (acknowledged, never completed: a fault
 * before the record, a reset without a stop), so that its running priority
 * is idle (0xff) again; else nothing at or below it is ever taken. Only
 * what this core may complete: its banked SGIs/PPIs and the SPIs targeted
 * at it alone; innermost (highest priority) first.
 */
#define GIC_DRAIN_MAX 8u
struct gic_drain {
	uint32_t rpr_entry;	/* running priority found (0xff: idle) */
	uint32_t n;		/* interrupts completed, in id[]/prio[] in order */
	uint32_t id[GIC_DRAIN_MAX];
	uint32_t prio[GIC_DRAIN_MAX];
	uint32_t rpr_left;	/* running priority after (0xff: idle) */
	uint32_t still_active;	/* own interrupts still active after */
	uint32_t still_last;	/* the last of them (highest ID) */
};
void gic_drain_own_active(struct gic_drain *dr);

#endif
