/* SPDX-License-Identifier: MIT */
/*
 * uio.h - the two UIO devices servod uses: "ocm-mailbox" (the OCM region
 * amp_lib works on) and "cycle-interrupt" (cycle_irq.h).
 */
#ifndef SERVOD_UIO_H
#define SERVOD_UIO_H

#include <stdint.h>

struct servod;

/* /dev/uioN whose name starts with prefix, its map0 mapped at *base (size,
 * offset of the device's registers in it): the open fd, or -1. */
int uio_open(struct servod *sd, const char *prefix, volatile uint8_t **base, uint32_t *size,
	     uint32_t *offs);

#endif
