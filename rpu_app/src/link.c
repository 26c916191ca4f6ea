/* SPDX-License-Identifier: MIT */
/*
 * link.c - heartbeat and attach through amp_lib (amp/amp.h).
 *
 * Until Linux has initialised the OCM layout, amp_servo_attach() fails
 * (AMP_E_PEER_ABSENT): the reason is logged once (and again whenever it
 * changes), the cycle and the stop protocol keep running, and the attach
 * is retried every BOARD_ATTACH_RETRY_CYCLES cycles. The heartbeat is
 * counted locally while detached and written to OCM once attached.
 */
#include <stdint.h>

#include "arch.h"
#include "board.h"
#include "link.h"
#include "log.h"

#ifndef HAVE_AMP_LIB
#define HAVE_AMP_LIB 0
#endif

#if HAVE_AMP_LIB
#include "amp/amp.h"

static struct amp_servo amp;
#endif

static volatile int attached;
static volatile uint32_t local_hb;
static uint32_t next_try;
static int last_err;

void link_init(void)
{
	attached = 0;
	local_hb = 0;
	next_try = 0;
	last_err = 1;	/* nothing reported yet */
#if HAVE_AMP_LIB
	amp = (struct amp_servo){ 0 };
#else
	log_printf("link: amp_lib servo side not linked; heartbeat kept locally\n");
#endif
}

void link_poll(uint32_t cycle)
{
#if HAVE_AMP_LIB
	int rc;

	if (attached || (int32_t)(cycle - next_try) < 0)
		return;
	next_try = cycle + BOARD_ATTACH_RETRY_CYCLES;
	rc = amp_servo_attach(&amp, (void *)(uintptr_t)BOARD_AMP_BASE, BOARD_AMP_SIZE);
	if (rc == AMP_OK) {
		compiler_barrier();
		attached = 1;
		log_printf("link: attached to amp_lib region %p epoch %u (cycle %u)\n",
			   (void *)(uintptr_t)BOARD_AMP_BASE, (unsigned)amp.epoch, (unsigned)cycle);
	} else if (rc != last_err) {
		log_printf("link: amp_servo_attach: %s (%d); retry every %u cycles\n",
			   amp_strerror(rc), rc, (unsigned)BOARD_ATTACH_RETRY_CYCLES);
	}
	last_err = rc;
#else
	(void)cycle;
#endif
}

void link_cycle(void)
{
	local_hb++;
#if HAVE_AMP_LIB
	if (attached)
		amp_servo_heartbeat(&amp);
#endif
}

int link_attached(void)
{
	return attached;
}

uint32_t link_heartbeat(void)
{
	return local_hb;
}

const char *link_backend(void)
{
	return HAVE_AMP_LIB ? "amp_lib" : "local";
}
