// SPDX-License-Identifier: MIT
/* session.c - the session state machine's transitions (session.h). */
#define _GNU_SOURCE
#include "session.h"

enum session_state session_next(enum session_state s, enum session_event ev)
{
	switch (ev) {
	case SEV_REGION_READY:
		return s == SESSION_CLOSED ? SESSION_OPEN : s;
	case SEV_SEEN_RUNNING:
		return s == SESSION_OPEN ? SESSION_RUNNING : s;
	case SEV_SEEN_OFFLINE:
		/* stopped, not a recovery: a new session for the next start
		 * (OPEN has not seen the servo run yet: the offline is the one
		 * its region was initialised in) */
		return s == SESSION_RUNNING ? SESSION_CLOSED : s;
	case SEV_CRASH_REPORTED:
		return s == SESSION_OPEN || s == SESSION_RUNNING ? SESSION_RECOVERING : s;
	case SEV_ATTACHED:
		return s == SESSION_RECOVERING ? SESSION_RUNNING : s;
	case SEV_LATCHED:
		return s == SESSION_OPEN || s == SESSION_RUNNING || s == SESSION_RECOVERING ? SESSION_FAULT : s;
	case SEV_RESET:
		return s == SESSION_FAULT ? SESSION_RECOVERING : s;
	case SEV_STOPPED:
		return s == SESSION_RUNNING || s == SESSION_RECOVERING ? SESSION_CLOSED : s;
	}
	return s;
}

void session_event(struct session *ss, enum session_event ev)
{
	ss->state = session_next(ss->state, ev);
}
