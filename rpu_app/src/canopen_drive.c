/* SPDX-License-Identifier: MIT */
/*
 * canopen_drive.c - the CiA 402 side of the CANopen master (see
 * canopen_master.h): the statusword decoded, and the controlword of each
 * cycle: the enable sequence, the acknowledgement of a latched fault and
 * the fault reset of a drive in Fault (bit 7 after a word with it clear,
 * held until the drive leaves Fault or the reset's time runs out). No
 * transport, no globals, no allocation, no library calls.
 */
#include <stdint.h>

#include "canopen_internal.h"

enum co_402_state co_402_decode(uint16_t sw)
{
	if ((sw & 0x4Fu) == 0x00u)
		return CO402_NOT_READY;
	if ((sw & 0x4Fu) == 0x40u)
		return CO402_SWITCH_ON_DISABLED;
	if ((sw & 0x6Fu) == 0x21u)
		return CO402_READY_TO_SWITCH_ON;
	if ((sw & 0x6Fu) == 0x23u)
		return CO402_SWITCHED_ON;
	if ((sw & 0x6Fu) == 0x27u)
		return CO402_OPERATION_ENABLED;
	if ((sw & 0x6Fu) == 0x07u)
		return CO402_QUICK_STOP_ACTIVE;
	if ((sw & 0x4Fu) == 0x0Fu)
		return CO402_FAULT_REACTION_ACTIVE;
	if ((sw & 0x4Fu) == 0x08u)
		return CO402_FAULT;
	return CO402_UNKNOWN;
}

const char *co_402_name(enum co_402_state s)
{
	switch (s) {
	case CO402_NOT_READY: return "not ready to switch on";
	case CO402_SWITCH_ON_DISABLED: return "switch on disabled";
	case CO402_READY_TO_SWITCH_ON: return "ready to switch on";
	case CO402_SWITCHED_ON: return "switched on";
	case CO402_OPERATION_ENABLED: return "operation enabled";
	case CO402_QUICK_STOP_ACTIVE: return "quick stop active";
	case CO402_FAULT_REACTION_ACTIVE: return "fault reaction active";
	case CO402_FAULT: return "fault";
	default: return "unknown";
	}
}

static int in_fault(const struct co_node *n)
{
	return n->state402 == CO402_FAULT || n->state402 == CO402_FAULT_REACTION_ACTIVE;
}

static void start_fault_reset(struct co_master *m, struct co_node *n)
{
	n->reset_active = 1;
	n->reset_sent = 0;
	n->reset_deadline = m->cycle + m->fault_reset_cycles;
	m->st.fault_resets++;
}

/* The operator's acknowledgement (co_master_acknowledge): the latched
 * fault and the drive's last EMCY code are cleared, and a drive in Fault
 * (or, if its state is not known yet, found in Fault later) is reset. */
void co_acknowledge(struct co_master *m, struct co_node *n)
{
	n->fault = 0;
	n->error_code = 0;
	n->emcy_last = 0;
	n->pdo_silent = 0;
	n->ack_wait = 0;
	if (n->phase != CO_PH_OPERATIONAL || n->state402 == CO402_UNKNOWN)
		n->ack_wait = 1;	/* its state is not known (yet): decided by its first TPDO1 */
	else if (in_fault(n))
		start_fault_reset(m, n);
}

/* The controlword of a running fault reset in *cw, 1; or 0 once the reset
 * has ended: the drive left Fault, or the time ran out (then the axis
 * faults: fault reset refused by drive), or a new fault came in. */
static int fault_reset_word(struct co_master *m, struct co_node *n, uint16_t *cw)
{
	if (n->fault || !in_fault(n)) {
		n->reset_active = 0;
		return 0;
	}
	if (co_expired(m, n->reset_deadline)) {
		n->reset_active = 0;
		m->st.fault_reset_refused++;
		co_raise_fault(m, n, CO_ERR_FAULT_RESET);
		return 0;
	}
	if (n->state402 == CO402_FAULT_REACTION_ACTIVE || (!n->reset_sent && (n->controlword & CO_CW_FAULT_RESET)))
		*cw = CO_CW_DISABLE_VOLTAGE;	/* bit 7 clear first: the reset is its rising edge */
	else
		*cw = CO_CW_FAULT_RESET;	/* then held until the drive leaves Fault */
	return 1;
}

uint16_t co_controlword(struct co_master *m, struct co_node *n)
{
	uint16_t cw;

	if (n->ack_wait && n->state402 != CO402_UNKNOWN) {
		n->ack_wait = 0;
		if (in_fault(n) && !n->fault)
			start_fault_reset(m, n);
	}
	if (n->reset_active && fault_reset_word(m, n, &cw))
		return cw;
	if (n->state402 == CO402_FAULT && !n->fault && n->enable_req)
		co_raise_fault(m, n, n->emcy_last ? n->emcy_last : CO_ERR_DRIVE_FAULT);
	if (!n->enable_req || n->fault)
		return n->state402 == CO402_QUICK_STOP_ACTIVE ? CO_CW_DISABLE_VOLTAGE : CO_CW_SHUTDOWN;
	switch (n->state402) {
	case CO402_READY_TO_SWITCH_ON:
		return CO_CW_SWITCH_ON;
	case CO402_SWITCHED_ON:
	case CO402_OPERATION_ENABLED:
		return CO_CW_ENABLE_OPERATION;
	case CO402_QUICK_STOP_ACTIVE:
		return CO_CW_DISABLE_VOLTAGE;
	default:	/* switch on disabled, not ready, fault reaction, unknown */
		return CO_CW_SHUTDOWN;
	}
}
