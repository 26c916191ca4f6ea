/* SPDX-License-Identifier: MIT */
/*
 * A thin C face of rpu_app/src/canopen_master.c for Python (ctypes), so
 * that test_rpu_canopen_drivesim.py can run the firmware's master against
 * the host drive simulator (servoamp.drivesim) without QEMU.
 */
#include <stddef.h>
#include <stdint.h>

#include "canopen_master.h"

size_t shim_master_size(void);
size_t shim_frame_size(void);
int shim_init(struct co_master *m, co_send_fn send, uint32_t period_us, const uint8_t *ids, uint32_t n);
int shim_node(const struct co_master *m, uint32_t idx, uint32_t *out);
void shim_stats(const struct co_master *m, uint32_t *out, uint32_t n);

size_t shim_master_size(void)
{
	return sizeof(struct co_master);
}

size_t shim_frame_size(void)
{
	return sizeof(struct can_frame);
}

int shim_init(struct co_master *m, co_send_fn send, uint32_t period_us, const uint8_t *ids, uint32_t n)
{
	struct co_config cfg = {
		.period_us = period_us, .hb_producer_ms = 20, .hb_consumer_ms = 60, .sdo_timeout_ms = 50,
		.boot_timeout_ms = 500, .boot_retries = 3, .sdo_retries = 2,
	};

	if (co_master_init(m, send, NULL, &cfg, ids, n))
		return -1;
	co_master_start(m);
	return 0;
}

/* phase, state402, fault, error_code, pos_actual, statusword, controlword, sdo_abort */
int shim_node(const struct co_master *m, uint32_t idx, uint32_t *out)
{
	const struct co_node *n = co_master_node(m, idx);

	if (!n)
		return -1;
	out[0] = n->phase;
	out[1] = n->state402;
	out[2] = n->fault;
	out[3] = n->error_code;
	out[4] = (uint32_t)n->pos_actual;
	out[5] = n->statusword;
	out[6] = n->controlword;
	out[7] = n->sdo_abort;
	return 0;
}

void shim_stats(const struct co_master *m, uint32_t *out, uint32_t n)
{
	struct co_stats st;
	const uint32_t *w = (const uint32_t *)&st;

	co_master_stats(m, &st);
	for (uint32_t i = 0; i < n && i < sizeof(st) / sizeof(uint32_t); i++)
		out[i] = w[i];
}
