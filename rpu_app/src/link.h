/* SPDX-License-Identifier: MIT */
#ifndef RPU_LINK_H
#define RPU_LINK_H

#include <stdint.h>

/*
 * The firmware's only interface to the OCM transport (amp_lib) and to the
 * application protocol (servoamp/servo_proto.h); link.c.
 */
struct link_stats {		/* cycle timing kept by main.c */
	uint32_t cycles, missed, overruns;
};

/* Diagnostics for the tests (read through the QEMU monitor by symbol). */
struct link_diag {
	uint32_t safestop_cycle;	/* amp cycle at which the safe stop began */
	uint32_t safestop_reason;
	uint32_t last_linux_beat_cycle;	/* amp cycle of Linux's last heartbeat before it */
	uint32_t standstill_cycle;	/* amp cycle at which every axis stood still */
};
extern volatile struct link_diag link_diag;

/* Debug hooks (SP_CMD_DEBUG; the QEMU tests without Linux write them
 * through the gdbstub by symbol). Cleared by link_init. */
struct link_debug {
	uint32_t slow_us;	/* SP_DEBUG_SLOW: extra busy time per cycle handler */
	uint32_t overload;	/* SP_DEBUG_OVERLOAD: the cycle interrupt re-pends itself
				 * (1 requested, 2 in effect) */
	uint32_t stray_req;	/* SP_DEBUG_STRAY_IRQ: 1 requested, 2 started (background) */
};
extern volatile struct link_debug link_debug;

void link_init(void);
/* Main loop: attach / retry, mailbox service. */
void link_poll(uint32_t cycle, const struct link_stats *ls);
/* Cycle interrupt: the exchange (t_entry: global timer at handler entry). */
void link_cycle(uint32_t t_entry, uint32_t lat_ns);
int link_attached(void);
/* A stop on request (remoteproc's STOP) seen: the servo line says
 * STOPPING before the heartbeat ends, so that Linux never takes the stop
 * for a stall (docs/amp-protocol.md section 3). Interrupts disabled. */
void link_stopping(void);
uint32_t link_heartbeat(void);
const char *link_backend(void);

#endif
