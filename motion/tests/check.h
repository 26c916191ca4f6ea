/* SPDX-License-Identifier: MIT */
/*
 * Tiny test harness for the motion tests, and a setpoint checker that is
 * independent of the planner: it only differentiates the int32 setpoints.
 */
#ifndef SERVOAMP_MOTION_CHECK_H
#define SERVOAMP_MOTION_CHECK_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "motion/motion.h"

struct test_case {
	const char *name;
	int (*fn)(void);
};

/* `prog` lists the cases with --list, runs all without arguments, or the
 * named ones.  Exit status 0 only if every case passed. */
int test_main(int argc, char **argv, const struct test_case *cases, size_t n);
void check_failf(const char *file, int line, const char *fmt, ...)
	__attribute__((format(printf, 3, 4)));

#define CHECK(cond, ...)                                                      \
	do {                                                                  \
		if (!(cond)) {                                                \
			check_failf(__FILE__, __LINE__, "CHECK(%s): ", #cond); \
			check_failf(NULL, 0, __VA_ARGS__);                    \
			return 1;                                             \
		}                                                             \
	} while (0)

/* Recorded setpoints of one run. */
struct trace {
	size_t n, cap;
	struct motion_setpoint *sp;
	enum motion_status final;
	struct motion_error err;
	bool has_err;
	struct motion_stats stats;
};

void trace_free(struct trace *tr);

/* Runs a program in synchronous mode, fed through the stream in chunks of
 * `chunk` bytes honouring XOFF/XON (or loaded in memory when chunk == 0),
 * until DONE/FAULT or max_cycles.  Returns 0 if the motion object could be
 * created. */
int run_program(const struct motion_config *cfg, const char *text,
		size_t chunk, uint64_t max_cycles, struct trace *tr);

/* Maxima measured by differentiating positions (units: mm, s). */
struct measured {
	double v[MOTION_MAX_AXES], a[MOTION_MAX_AXES], j[MOTION_MAX_AXES];
	size_t v_at[MOTION_MAX_AXES], a_at[MOTION_MAX_AXES], j_at[MOTION_MAX_AXES];
	double ff_err[MOTION_MAX_AXES]; /* |feed-forward - backward difference| */
	double ff_max[MOTION_MAX_AXES];
};
void measure(const struct trace *tr, double period_s, double ipm,
	     struct measured *out);

/* Checks velocity, acceleration (and jerk when cfg->jerk_limited), travel
 * and feed-forward against cfg with the quantisation allowance.  Returns 0
 * or -1 with a reason in why. */
int check_limits(const struct trace *tr, const struct motion_config *cfg,
		 char *why, size_t whylen);

/* Position of setpoint i, axis k, in mm. */
double sp_mm(const struct trace *tr, size_t i, unsigned k, double ipm);

#endif
