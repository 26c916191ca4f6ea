/* SPDX-License-Identifier: MIT */
/* idle_timer.c - the background loop's bounded wait (idle_timer.h). */
#include "arch.h"
#include "board.h"
#include "idle_timer.h"
#include "irq.h"

#define TWD_LOAD 0x00u
#define TWD_CTRL 0x08u
#define TWD_ISR  0x0cu
#define TWD_CTRL_RUN 0x7u	/* enable, auto-reload, interrupt */
#define IDLE_PRIORITY 0xe0u	/* below the cycle (BOARD_CYCLE_PRIORITY), above PMR */

static volatile uint32_t wakes;

static void idle_clear(void *arg)
{
	(void)arg;
	mmio_write32(BOARD_TWD_BASE + TWD_ISR, 1u);
}

static void idle_handler(void *arg)
{
	(void)arg;
	wakes++;
}

int idle_timer_start(void)
{
	mmio_write32(BOARD_TWD_BASE + TWD_CTRL, 0);
	mmio_write32(BOARD_TWD_BASE + TWD_ISR, 1u);
	if (irq_register(BOARD_TWD_IRQ, idle_handler, idle_clear, IRQ_TRIGGER_EDGE, 0) ||
	    irq_set_priority(BOARD_TWD_IRQ, IDLE_PRIORITY))
		return -1;
	mmio_write32(BOARD_TWD_BASE + TWD_LOAD, BOARD_IDLE_WAKE_LOAD);
	mmio_write32(BOARD_TWD_BASE + TWD_CTRL, TWD_CTRL_RUN);
	return irq_enable(BOARD_TWD_IRQ);
}

void idle_timer_stop(void)
{
	mmio_write32(BOARD_TWD_BASE + TWD_CTRL, 0);
	mmio_write32(BOARD_TWD_BASE + TWD_ISR, 1u);
}

uint32_t idle_timer_wakes(void)
{
	return wakes;
}
