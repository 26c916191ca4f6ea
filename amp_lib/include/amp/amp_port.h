/* SPDX-License-Identifier: MIT */
/*
 * amp_port.h - the porting surface of amp_lib. A port is one header,
 * amp_port_impl.h, found on the include path (amp_lib/port/<port>/), that
 * defines:
 *
 *   AMP_PORT_LOAD32(p)          32-bit load from shared memory, not elided
 *   AMP_PORT_STORE32(p, v)      32-bit store to shared memory, not elided
 *   AMP_PORT_MB()               full barrier between the cores (both
 *                               directions; orders shared-memory accesses)
 *   AMP_PORT_RMB(), AMP_PORT_WMB()  optional: load-load / store-store
 *                               ordering only (default: AMP_PORT_MB)
 *   AMP_PORT_LOAD_ACQ(p)        optional: load + RMB (semaphores, sequences)
 *   AMP_PORT_STORE_REL(p, v)    optional: MB + store (everything before
 *                               it, loads and stores, is ordered before
 *                               the store; nothing after it needs to be:
 *                               docs/amp-protocol.md section 8 pairs
 *                               each barrier)
 *   AMP_PORT_CACHE_CLEAN(a, n)  write back lines [a, a+n) (if cached)
 *   AMP_PORT_CACHE_INVAL(a, n)  discard lines [a, a+n) (if cached)
 *   AMP_PORT_RELAX()            pause inside a polling loop
 *   AMP_PORT_SIGNAL()           wake a peer waiting in AMP_PORT_RELAX (may
 *                               be empty; SEV on ARM)
 *   amp_ticks_t amp_port_ticks(void)   free-running uint32_t tick counter
 *   AMP_PORT_TICKS_PER_US       its rate
 *
 * Ports shipped: posix (host tests: a shared mapping stands in for OCM),
 * linux (Linux userspace on the target: an mmap'ed OCM region),
 * baremetal-armv7 (Cortex-A9 and Cortex-R5 firmware).
 */
#ifndef AMP_PORT_H
#define AMP_PORT_H

#include <stdint.h>

typedef uint32_t amp_ticks_t;

#include "amp_port_impl.h"

#ifndef AMP_PORT_RMB
#define AMP_PORT_RMB() AMP_PORT_MB()
#endif
#ifndef AMP_PORT_WMB
#define AMP_PORT_WMB() AMP_PORT_MB()
#endif

#ifndef AMP_PORT_LOAD_ACQ
static inline uint32_t amp_port__load_acq(const uint32_t *p)
{
	uint32_t v = AMP_PORT_LOAD32(p);

	AMP_PORT_RMB();
	return v;
}
#define AMP_PORT_LOAD_ACQ(p) amp_port__load_acq(p)
#endif

#ifndef AMP_PORT_STORE_REL
/* No barrier after the store: no step of amp_lib orders a later access
 * after a release store (the next release store's own MB orders it before
 * that one, which is all the protocol needs). On ARMv7 this is one DMB per
 * release store instead of two. */
#define AMP_PORT_STORE_REL(p, v) do { AMP_PORT_MB(); AMP_PORT_STORE32((p), (v)); } while (0)
#endif

#ifndef AMP_PORT_SIGNAL
#define AMP_PORT_SIGNAL() do { } while (0)
#endif

#endif /* AMP_PORT_H */
