/* SPDX-License-Identifier: MIT */
#ifndef RPU_IRQ_H
#define RPU_IRQ_H

#include <stdint.h>

#include "board.h"

/*
 * Interrupt descriptor table: one descriptor per GIC interrupt
 * ID with a handler, a clear function (clears the flag at the source) and
 * the trigger type; registered at init, dispatched by irq_dispatch().
 *
 * Order in the dispatcher (IRQs masked unless stated):
 *   IAR read -> recorded as in service (nesting count +1) -> latency probe ->
 *   edge:  clear(), then the handler with IRQs unmasked (a new edge during
 *          the handler is latched again by the GIC, none is lost);
 *   level: the handler with IRQs unmasked, then clear() (the line must be
 *          low before EOI or the GIC re-takes it at once);
 *   statistics -> nesting count -1 -> EOI.
 * The record comes before anything that can fault: an interrupt
 * acknowledged and not completed is always in the record, and the fault
 * handler and the stop path complete it (irq_complete_all), so no
 * interrupt stays active in this core's CPU interface across a restart.
 * An interrupt taken without a registered handler (not ours, yet routed to
 * this core) is counted, disabled at the distributor (PPI/SPI; SGIs only
 * counted) and completed: a level source nobody clears cannot storm.
 * With IRQ_NESTING (default 1) the handler runs with IRQs unmasked; the
 * GIC's running priority lets only higher-priority interrupts (lower
 * value, other group under BPR) preempt it, so a handler never re-enters
 * itself and the depth is bounded by the number of priority groups used.
 */
#define IRQ_MAX_ID BOARD_GIC_IDS	/* the GIC's IDs (per platform: board_config.h) */
#define IRQ_LATENCY_NONE 0xffffffffu

enum irq_trigger { IRQ_TRIGGER_LEVEL = 0, IRQ_TRIGGER_EDGE = 1 };

typedef void (*irq_handler_t)(void *arg);
typedef void (*irq_clear_t)(void *arg);
/* ns from the source's expected fire point to now, or IRQ_LATENCY_NONE. */
typedef uint32_t (*irq_latency_t)(void *arg);

struct irq_stats {
	uint32_t count;
	uint32_t lat_n;		/* samples with a latency */
	uint32_t lat_min_ns;
	uint32_t lat_max_ns;
	uint64_t lat_sum_ns;
	uint32_t nest_max;	/* deepest nesting seen when this one entered */
};

void irq_init(void);
/* 0, or -1 if id is out of range / already registered. */
int irq_register(uint32_t id, irq_handler_t handler, irq_clear_t clear,
		 enum irq_trigger trigger, void *arg);
int irq_set_priority(uint32_t id, uint32_t prio);
int irq_set_latency_probe(uint32_t id, irq_latency_t probe);
int irq_enable(uint32_t id);
/* Stop path: disable every registered interrupt, EOI any still in service. */
void irq_release_all(void);
/* EOI every interrupt acknowledged and not completed (innermost first);
 * their IDs in ids[0..max), innermost first; returns how many. IRQ-safe,
 * also for the fault handler. */
uint32_t irq_complete_all(uint32_t *ids, uint32_t max);

/* Debug (SP_DEBUG_IRQ_ABORT): the next dispatch of id takes a data abort
 * (the SVC stack's guard page) right after its acknowledge. -1 without the
 * MMU (no guard page) or for an id out of range. */
int irq_debug_abort_next(uint32_t id);

void irq_get_stats(uint32_t id, struct irq_stats *st);
uint32_t irq_nest_max(void);
uint32_t irq_nest_now(void);
uint32_t irq_spurious(void);
uint32_t irq_unhandled(void);		/* interrupts taken without a handler */
uint32_t irq_disabled(void);		/* of those, disabled at the GIC distributor */
uint32_t irq_disabled_last(void);	/* ID of the last one disabled (0: none) */
uint32_t irq_taken(void);		/* interrupts handled by a registered handler (wraps) */

void irq_dispatch(void);	/* called by irq_entry (start.S) */

#endif
