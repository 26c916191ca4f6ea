/* SPDX-License-Identifier: MIT */
/*
 * gic.c - this core's use of the shared GIC.
 *
 * Rules (docs/platform-notes.md, GIC pitfalls):
 *  - never write GICD_CTLR (Linux owns the distributor);
 *  - touch only the firmware's own interrupts: byte accesses for
 *    IPRIORITYR/ITARGETSR, write-1 registers (ISENABLER/ICENABLER/
 *    ICPENDR) with only the own bit set; ICFGR is word-only and shared by
 *    16 interrupts, so it is read and written back only if the own field
 *    must change (race window documented in rpu_app/README.md);
 *  - SPIs target this core only (ITARGETSR = 1 << MPIDR.Aff0, 0x02 on
 *    CPU1), never both cores;
 *  - enable only this core's CPU interface (banked GICC registers);
 *  - complete (EOIR) only interrupts this core acknowledged: at start,
 *    those an earlier run left active (gic_drain_own_active).
 */
#include "arch.h"
#include "board.h"
#include "gic.h"

#define GICD_CTLR        0x000u
#define GICD_TYPER       0x004u
#define GICD_ISENABLER   0x100u
#define GICD_ICENABLER   0x180u
#define GICD_ISPENDR     0x200u
#define GICD_ICPENDR     0x280u
#define GICD_ISACTIVER   0x300u	/* GICv1: read-only active bits (ICDABR) */
#define GICD_IPRIORITYR  0x400u
#define GICD_ITARGETSR   0x800u
#define GICD_ICFGR       0xc00u
#define GICD_SGIR        0xf00u

#define GICC_CTLR 0x00u
#define GICC_PMR  0x04u
#define GICC_BPR  0x08u
#define GICC_IAR  0x0cu
#define GICC_EOIR 0x10u
#define GICC_RPR  0x14u

#define D(off) (BOARD_GICD_BASE + (off))
#define C(off) (BOARD_GICC_BASE + (off))

int gic_dist_enabled(void)
{
	return (mmio_read32(D(GICD_CTLR)) & 1u) != 0;
}

/* A GIC of this core's own (the RPU's): enable its distributor. A GIC
 * shared with Linux (the A9's) is never enabled here (BOARD_GIC_OWNED). */
void gic_dist_enable(void)
{
	mmio_write32(D(GICD_CTLR), 1u);
	dsb();
}

/*
 * This core's CPU interface as a target mask: GICD_ITARGETSR0..7 (the
 * SGIs', banked) read as the reading core's own mask (GICv1/v2), which is
 * how Linux's GIC driver finds it too. MPIDR would not do on every chip
 * (QEMU gives the ZynqMP's R5s Aff0 4 and 5, their GIC interfaces are 0
 * and 1).
 */
static uint8_t gic_self_mask(void)
{
	return mmio_read8(D(GICD_ITARGETSR));
}

static uint32_t gic_self_cpu(void)
{
	return (uint32_t)__builtin_ctz(gic_self_mask() | 0x100u);
}

void gic_cpu_init(uint32_t pmr, uint32_t bpr)
{
	mmio_write32(C(GICC_CTLR), 0);
	mmio_write32(C(GICC_PMR), pmr);
	mmio_write32(C(GICC_BPR), bpr);
	mmio_write32(C(GICC_CTLR), 1u);
	dsb();
}

void gic_cpu_disable(void)
{
	mmio_write32(C(GICC_CTLR), 0);
	mmio_write32(C(GICC_PMR), 0);
	dsb();
}

void gic_irq_config(uint32_t id, uint32_t prio, int level)
{
	uint32_t bit = 1u << (id & 31u);

	mmio_write32(D(GICD_ICENABLER + 4u * (id / 32u)), bit);
	dsb();
	mmio_write8(D(GICD_IPRIORITYR + id), (uint8_t)prio);
	if (id >= 32u) {
		uint32_t reg = D(GICD_ICFGR + 4u * (id / 16u));
		uint32_t shift = 2u * (id & 15u) + 1u;	/* bit 1 of the field: edge */
		uint32_t v = mmio_read32(reg);
		uint32_t want = level ? (v & ~(1u << shift)) : (v | (1u << shift));

		if (want != v)
			mmio_write32(reg, want);
		mmio_write8(D(GICD_ITARGETSR + id), gic_self_mask());
	}
	mmio_write32(D(GICD_ICPENDR + 4u * (id / 32u)), bit);
	dsb();
}

void gic_irq_enable(uint32_t id)
{
	mmio_write32(D(GICD_ISENABLER + 4u * (id / 32u)), 1u << (id & 31u));
	dsb();
}

void gic_irq_disable(uint32_t id)
{
	mmio_write32(D(GICD_ICENABLER + 4u * (id / 32u)), 1u << (id & 31u));
	dsb();
	mmio_write32(D(GICD_ICPENDR + 4u * (id / 32u)), 1u << (id & 31u));
	dsb();
}

void gic_irq_pend(uint32_t id)
{
	mmio_write32(D(GICD_ISPENDR + 4u * (id / 32u)), 1u << (id & 31u));
	dsb();
}

uint32_t gic_ack(void)
{
	return mmio_read32(C(GICC_IAR));
}

void gic_eoi(uint32_t iar)
{
	mmio_write32(C(GICC_EOIR), iar);
}

uint32_t gic_running_priority(void)
{
	return mmio_read32(C(GICC_RPR)) & 0xffu;
}

void gic_sgi_self(uint32_t id)
{
	dsb();
	*gic_sgir() = gic_sgi_self_word(id);
}

volatile uint32_t *gic_sgir(void)
{
	return (volatile uint32_t *)D(GICD_SGIR);
}

uint32_t gic_sgi_self_word(uint32_t id)
{
	return (2u << 24) | (id & 15u);	/* TargetListFilter = 0b10: this core only */
}

static int gic_active(uint32_t id)
{
	return (mmio_read32(D(GICD_ISACTIVER + 4u * (id / 32u))) >> (id & 31u)) & 1u;
}

/* Active and this core's to complete: an SGI or PPI (banked: this core's
 * own), or an SPI targeted at this core alone (no other core can have
 * acknowledged it; Linux never targets an SPI of its own at this core). */
static int gic_own_active(uint32_t id)
{
	if (!gic_active(id))
		return 0;
	return id < 32u || mmio_read8(D(GICD_ITARGETSR + id)) == gic_self_mask();
}

static uint32_t gic_num_irqs(void)
{
	uint32_t n = 32u * ((mmio_read32(D(GICD_TYPER)) & 0x1fu) + 1u);

	return n < 1020u ? n : 1020u;
}

void gic_drain_own_active(struct gic_drain *dr)
{
	uint32_t nirq = gic_num_irqs();

	dr->rpr_entry = gic_running_priority();
	dr->n = 0;
	dr->still_active = 0;
	/* Innermost first: an interrupt preempts only interrupts of lower
	 * priority, so the active one with the highest priority (lowest
	 * value) was acknowledged last and is completed first, as the GIC
	 * requires (GICv1/v2: EOIs in the reverse order of the acknowledges;
	 * GICv1 has no ICACTIVER to clear an active bit otherwise). */
	while (dr->n < GIC_DRAIN_MAX && gic_running_priority() != 0xffu) {
		uint32_t best = nirq, best_prio = 0x100u;

		for (uint32_t id = 0; id < nirq; id++) {
			uint32_t p;

			if (!gic_own_active(id))
				continue;
			p = mmio_read8(D(GICD_IPRIORITYR + id));
			if (p < best_prio) {
				best = id;
				best_prio = p;
			}
		}
		if (best == nirq)
			break;	/* busy, but with nothing of this core's active */
		/* An SGI's EOIR names its source: this core's own SGIs are sent
		 * to itself (gic_sgi_self). */
		dsb();
		gic_eoi(best < 16u ? best | (gic_self_cpu() << 10) : best);
		dsb();
		dr->id[dr->n] = best;
		dr->prio[dr->n] = best_prio;
		dr->n++;
		if (gic_active(best))
			break;	/* the EOI did not complete it */
	}
	dr->rpr_left = gic_running_priority();
	for (uint32_t id = 0; id < nirq; id++) {
		if (gic_own_active(id)) {
			dr->still_active++;
			dr->still_last = id;
		}
	}
}
