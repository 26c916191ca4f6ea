/* SPDX-License-Identifier: MIT */
/*
 * servod.h - what servod and ampctl share besides servoamp/servo_proto.h:
 * the local control socket. One request line per connection
 * ("status", "stats", "param list", "param get NAME", "param set NAME VALUE",
 * "resume", "fault [reset]", "debug hang|crash|fault|badparam|stack", "raw CMD NBYTES [WORD...]",
 * "run FILE", "stop"); the answer is
 * one status line, "OK" or "ERR <code> <message>", then the body, then EOF.
 */
#ifndef SERVOD_H
#define SERVOD_H

#define SERVOD_SOCKET "/run/servod.sock"
#define SERVOD_PARAMS "/var/lib/servod/params"

/* ERR codes = ampctl exit statuses. */
enum servod_err {
	SE_OK = 0,
	SE_USAGE = 1,		/* bad request */
	SE_NOSERVOD = 2,	/* (ampctl only) servod not reachable */
	SE_OFFLINE = 3,		/* servo not running / not attached */
	SE_TIMEOUT = 4,		/* the servo did not answer in time */
	SE_UNKNOWN = 5,		/* unknown parameter */
	SE_VALUE = 6,		/* bad value: out of range, wrong type */
	SE_SERVO = 7,		/* the servo answered with another error */
	SE_IO = 8,		/* servod could not store the parameter file */
	SE_PROGRAM = 9,		/* G-code program refused (unreadable, malformed: file:line:col) */
	SE_BUSY = 10,		/* a program is running (or servod has too many connections) */
	SE_DENIED = 11,		/* the caller may not use servod's socket (root and servod's uid may) */
};

#endif
