/* SPDX-License-Identifier: MIT */
#include <stddef.h>
#include <stdint.h>

#include "arch.h"
#include "gic.h"
#include "irq.h"
#include "memprot.h"

#ifndef IRQ_NESTING
#define IRQ_NESTING 1
#endif

#define NEST_MAX 8u
#define DEFAULT_PRIORITY 0xa0u

struct irq_desc {
	irq_handler_t handler;
	irq_clear_t clear;
	irq_latency_t latency;
	void *arg;
	uint8_t trigger;
	uint8_t registered;
	uint8_t enabled;
	uint8_t prio;
	struct irq_stats st;
};

static struct irq_desc idt[IRQ_MAX_ID];
static volatile uint32_t nest;
static uint32_t nest_max;
/* IAR values acknowledged and not yet completed, outermost first; written
 * right after the acknowledge, before anything that can fault, so that
 * every path (irq_release_all, the fault handler) completes them. */
static volatile uint32_t in_service[NEST_MAX];
static uint32_t spurious, unhandled, disabled, disabled_last;
static volatile uint32_t taken;	/* interrupts handled (a registered handler ran) */
/* Debug (SP_DEBUG_IRQ_ABORT): ID + 1 of the interrupt whose next dispatch
 * faults right after its acknowledge; 0: off. The QEMU tests without Linux
 * write it through the gdbstub by symbol. Cleared by irq_init. */
volatile uint32_t irq_debug_abort;

void irq_init(void)
{
	for (uint32_t i = 0; i < IRQ_MAX_ID; i++)
		idt[i] = (struct irq_desc){ 0 };
	nest = 0;
	nest_max = 0;
	spurious = unhandled = disabled = disabled_last = 0;
	irq_debug_abort = 0;
}

int irq_debug_abort_next(uint32_t id)
{
	if (id >= IRQ_MAX_ID || !memprot_enabled())
		return -1;	/* no guard page: nothing would fault */
	irq_debug_abort = id + 1u;
	return 0;
}

/* The access a stack overflow would make: a data abort on the SVC stack's
 * guard (the platform's memprot), taken inside the dispatcher. */
static __attribute__((noinline)) void irq_debug_fault(void)
{
	mmio_write32(memprot_stack_guard_start(), 0);
}

int irq_register(uint32_t id, irq_handler_t handler, irq_clear_t clear,
		 enum irq_trigger trigger, void *arg)
{
	struct irq_desc *d;

	if (id >= IRQ_MAX_ID || !handler || idt[id].registered)
		return -1;
	d = &idt[id];
	d->handler = handler;
	d->clear = clear;
	d->latency = NULL;
	d->arg = arg;
	d->trigger = (uint8_t)trigger;
	d->prio = DEFAULT_PRIORITY;
	d->st = (struct irq_stats){ .lat_min_ns = UINT32_MAX };
	d->registered = 1;
	gic_irq_config(id, d->prio, trigger == IRQ_TRIGGER_LEVEL);
	return 0;
}

int irq_set_priority(uint32_t id, uint32_t prio)
{
	if (id >= IRQ_MAX_ID || !idt[id].registered || prio > 0xffu)
		return -1;
	idt[id].prio = (uint8_t)prio;
	gic_irq_config(id, prio, idt[id].trigger == IRQ_TRIGGER_LEVEL);
	if (idt[id].enabled)
		gic_irq_enable(id);
	return 0;
}

int irq_set_latency_probe(uint32_t id, irq_latency_t probe)
{
	if (id >= IRQ_MAX_ID || !idt[id].registered)
		return -1;
	idt[id].latency = probe;
	return 0;
}

int irq_enable(uint32_t id)
{
	if (id >= IRQ_MAX_ID || !idt[id].registered)
		return -1;
	idt[id].enabled = 1;
	gic_irq_enable(id);
	return 0;
}

void irq_release_all(void)
{
	uint32_t flags = irq_save();

	for (uint32_t id = 0; id < IRQ_MAX_ID; id++) {
		if (idt[id].registered) {
			gic_irq_disable(id);
			idt[id].enabled = 0;
		}
	}
	(void)irq_complete_all(0, 0);
	irq_restore(flags);
}

uint32_t irq_complete_all(uint32_t *ids, uint32_t max)
{
	uint32_t flags = irq_save(), n = 0;

	/* Interrupts left active (a fault inside a handler or right after
	 * the acknowledge, a stop from a handler): complete them innermost
	 * first (the reverse order of their acknowledge, as the GIC wants)
	 * so the CPU interface is idle on restart. */
	while (nest) {
		uint32_t i = nest - 1u;

		if (i < NEST_MAX) {
			uint32_t iar = in_service[i];

			dsb();
			gic_eoi(iar);
			if (n < max)
				ids[n] = iar & 0x3ffu;
			n++;
		}
		nest = i;
	}
	dsb();
	irq_restore(flags);
	return n;
}

void irq_get_stats(uint32_t id, struct irq_stats *st)
{
	uint32_t flags = irq_save();

	*st = id < IRQ_MAX_ID ? idt[id].st : (struct irq_stats){ 0 };
	irq_restore(flags);
}

uint32_t irq_nest_max(void)
{
	return nest_max;
}

uint32_t irq_nest_now(void)
{
	return nest;
}

uint32_t irq_spurious(void)
{
	return spurious;
}

uint32_t irq_unhandled(void)
{
	return unhandled;
}

uint32_t irq_disabled(void)
{
	return disabled;
}

uint32_t irq_disabled_last(void)
{
	return disabled_last;
}

uint32_t irq_taken(void)
{
	return taken;
}

void irq_dispatch(void)
{
	uint32_t iar = gic_ack();
	uint32_t id = iar & 0x3ffu;
	uint32_t lat = IRQ_LATENCY_NONE, depth;
	struct irq_desc *d;

	if (id >= 1020u) {
		spurious++;
		return;		/* no EOI for a spurious ID */
	}
	/* Recorded first: from here on a fault (the latency probe, the
	 * handler, a stack overflow) leaves a record the fault handler and
	 * irq_release_all complete; the slot is written before the count
	 * covers it. */
	depth = nest + 1u;
	if (depth <= NEST_MAX)
		in_service[depth - 1u] = iar;
	compiler_barrier();
	nest = depth;
	if (depth > nest_max)
		nest_max = depth;

	if (irq_debug_abort == id + 1u) {
		irq_debug_abort = 0;
		irq_debug_fault();
	}
	d = id < IRQ_MAX_ID ? &idt[id] : NULL;
	if (d && d->latency)
		lat = d->latency(d->arg);

	if (!d || !d->registered) {
		/* Not ours, yet routed to this core: count it, disable it at
		 * the distributor (a level source nobody clears would storm
		 * and starve everything below its priority), complete it.
		 * SGIs cannot be disabled; they are edges and only counted. */
		unhandled++;
		if (id >= 16u) {
			gic_irq_disable(id);
			disabled++;
			disabled_last = id;
		}
	} else {
		if (d->trigger == IRQ_TRIGGER_EDGE && d->clear)
			d->clear(d->arg);
#if IRQ_NESTING
		cpu_irq_enable();
#endif
		d->handler(d->arg);
#if IRQ_NESTING
		cpu_irq_disable();
#endif
		if (d->trigger == IRQ_TRIGGER_LEVEL && d->clear)
			d->clear(d->arg);

		d->st.count++;
		taken++;
		if (depth > d->st.nest_max)
			d->st.nest_max = depth;
		if (lat != IRQ_LATENCY_NONE) {
			d->st.lat_n++;
			d->st.lat_sum_ns += lat;
			if (lat < d->st.lat_min_ns)
				d->st.lat_min_ns = lat;
			if (lat > d->st.lat_max_ns)
				d->st.lat_max_ns = lat;
		}
	}
	nest = depth - 1u;
	dsb();
	gic_eoi(iar);
}
