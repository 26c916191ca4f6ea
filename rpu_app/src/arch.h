/* SPDX-License-Identifier: MIT */
/*
 * arch.h - Cortex-A9 (ARMv7-A) helpers: MMIO, barriers, interrupt masking,
 * CP15 accessors. Header-only, freestanding.
 */
#ifndef RPU_ARCH_H
#define RPU_ARCH_H

#include <stdint.h>

#define MODE_USR 0x10u
#define MODE_FIQ 0x11u
#define MODE_IRQ 0x12u
#define MODE_SVC 0x13u
#define MODE_ABT 0x17u
#define MODE_UND 0x1bu
#define MODE_SYS 0x1fu
#define CPSR_I   (1u << 7)
#define CPSR_F   (1u << 6)

static inline uint32_t mmio_read32(uintptr_t a)
{
	return *(const volatile uint32_t *)a;
}

static inline void mmio_write32(uintptr_t a, uint32_t v)
{
	*(volatile uint32_t *)a = v;
}

static inline void mmio_write8(uintptr_t a, uint8_t v)
{
	*(volatile uint8_t *)a = v;
}

static inline uint8_t mmio_read8(uintptr_t a)
{
	return *(const volatile uint8_t *)a;
}

#define dmb() __asm__ volatile("dmb sy" ::: "memory")
#define dsb() __asm__ volatile("dsb sy" ::: "memory")
#define isb() __asm__ volatile("isb" ::: "memory")
#define wfi() __asm__ volatile("wfi" ::: "memory")
#define compiler_barrier() __asm__ volatile("" ::: "memory")

static inline uint32_t cpsr_read(void)
{
	uint32_t v;
	__asm__ volatile("mrs %0, cpsr" : "=r"(v) :: "memory");
	return v;
}

/* Mask IRQs, return the previous CPSR for irq_restore(). */
static inline uint32_t irq_save(void)
{
	uint32_t v = cpsr_read();
	__asm__ volatile("cpsid i" ::: "memory");
	return v;
}

static inline void irq_restore(uint32_t cpsr)
{
	if (!(cpsr & CPSR_I))
		__asm__ volatile("cpsie i" ::: "memory");
}

static inline void cpu_irq_enable(void)
{
	__asm__ volatile("cpsie i" ::: "memory");
}

static inline void cpu_irq_disable(void)
{
	__asm__ volatile("cpsid i" ::: "memory");
}

#define CP15_READ(op1, crn, crm, op2) ({ uint32_t v_; \
	__asm__ volatile("mrc p15, " #op1 ", %0, " #crn ", " #crm ", " #op2 : "=r"(v_) :: "memory"); v_; })
#define CP15_WRITE(op1, crn, crm, op2, v) \
	__asm__ volatile("mcr p15, " #op1 ", %0, " #crn ", " #crm ", " #op2 :: "r"((uint32_t)(v)) : "memory")

static inline uint32_t mpidr_cpu(void)
{
	return CP15_READ(0, c0, c0, 5) & 0x3u;
}

#endif /* RPU_ARCH_H */
