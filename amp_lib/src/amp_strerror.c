// SPDX-License-Identifier: MIT
/* amp_strerror.c - names of the AMP_E_* codes (kept out of the servo core
 * image unless the firmware calls it). */
#include "amp/amp.h"

const char *amp_strerror(int err)
{
	switch (err) {
	case AMP_OK: return "ok";
	case AMP_E_PEER_ABSENT: return "peer absent";
	case AMP_E_PEER_ERROR: return "peer error";
	case AMP_E_TIMEOUT: return "timeout";
	case AMP_E_PROTO: return "protocol violation";
	case AMP_E_INVAL: return "invalid argument";
	case AMP_E_LAYOUT: return "layout mismatch";
	case AMP_E_BUSY: return "busy";
	case AMP_E_NOSPC: return "payload too large";
	case AMP_E_STALLED: return "peer stalled";
	case AMP_E_FEEDBACK: return "no valid feedback";
	case AMP_E_PEER_STOPPING: return "peer stopping on request";
	default: return "unknown error";
	}
}
