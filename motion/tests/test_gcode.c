/* SPDX-License-Identifier: MIT */
/* Decoder tests: supported words, and each class of malformed input is
 * reported with its line, column and reason. */
#define _GNU_SOURCE /* M_PI */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "gcode.h"

static struct motion_config cfg3(void)
{
	struct motion_config c;

	motion_config_default(&c);
	return c;
}

/* Decodes `prog` line by line; returns the index (1-based) of the first
 * failing line, 0 if none failed. */
static uint32_t decode_all(const char *prog, struct motion_error *err,
			   struct gc_block *last, struct gc_state *st)
{
	struct motion_config c = cfg3();
	uint32_t line = 0;

	gc_init(st, &c);
	memset(err, 0, sizeof(*err));
	while (*prog) {
		const char *nl = strchr(prog, '\n');
		size_t len = nl ? (size_t)(nl - prog) : strlen(prog);
		line++;
		if (gc_line(st, prog, len, line, last, err))
			return line;
		prog += len + (nl ? 1 : 0);
	}
	return 0;
}

static int t_decode_basic(void)
{
	struct motion_error e;
	struct gc_block b;
	struct gc_state st;

	CHECK(decode_all("G1 X1 Y2 Z3 F600", &e, &b, &st) == 0, "%s", e.msg);
	CHECK(b.kind == GC_LINE && b.end[0] == 1 && b.end[1] == 2 && b.end[2] == 3,
	      "line block wrong");
	CHECK(fabs(b.feed - 10.0) < 1e-12, "feed %f mm/s", b.feed);
	CHECK(decode_all("G0 X-1.5", &e, &b, &st) == 0 && b.kind == GC_RAPID &&
		      b.end[0] == -1.5, "rapid");
	CHECK(decode_all("G4 P1.5", &e, &b, &st) == 0 && b.kind == GC_DWELL &&
		      b.dwell == 1.5, "dwell");
	CHECK(decode_all("G1 X1 F60\nM2", &e, &b, &st) == 0 && st.ended, "M2");
	CHECK(decode_all("G1 X1 F60 M30", &e, &b, &st) == 0 && st.ended &&
		      b.kind == GC_LINE, "M30 with motion");
	CHECK(decode_all("G2 X10 Y0 I5 F60", &e, &b, &st) == 0 && b.kind == GC_ARC &&
		      b.sweep < 0 && fabs(fabs(b.sweep) - M_PI) < 1e-12, "G2 half circle");
	CHECK(decode_all("G3 I5 F60", &e, &b, &st) == 0 && b.kind == GC_ARC &&
		      fabs(b.sweep - 2 * M_PI) < 1e-12, "full circle");
	CHECK(decode_all("G3 I5 P3 F60", &e, &b, &st) == 0 &&
		      fabs(b.sweep - 6 * M_PI) < 1e-12, "three turns");
	/* numbers: exact decimal conversion, signs, leading dot */
	CHECK(decode_all("G1 X.5 Y-.25 Z+3. F1", &e, &b, &st) == 0 && b.end[0] == 0.5 &&
		      b.end[1] == -0.25 && b.end[2] == 3.0, "number forms");
	CHECK(decode_all("G1 X0.1 F1", &e, &b, &st) == 0 && b.end[0] == 0.1, "0.1 exact");
	CHECK(decode_all("G1 X123.456000000000000 F1", &e, &b, &st) == 0 &&
		      b.end[0] == 123.456, "trailing zeros");
	/* spaces between letter and number, lower case */
	CHECK(decode_all("g1 x 2 f 60", &e, &b, &st) == 0 && b.end[0] == 2, "spaces");
	/* modal motion continues */
	CHECK(decode_all("G1 X1 F60\nX2\nY3", &e, &b, &st) == 0 && b.kind == GC_LINE &&
		      b.end[0] == 2 && b.end[1] == 3, "modal G1");
	/* empty and comment-only lines give no block */
	CHECK(decode_all("(hello)\n; world\n\n%", &e, &b, &st) == 0 && b.kind == GC_NONE,
	      "comment lines");
	return 0;
}

struct err_case {
	const char *prog;
	uint32_t line, col;
	enum motion_errcode code;
	const char *needle; /* part of the message */
};

static const struct err_case err_cases[] = {
	{ "G1 X1 F100\nG41 X2", 2, 1, MOTION_E_UNSUPPORTED, "G41" },
	{ "G5.1 X1", 1, 1, MOTION_E_UNSUPPORTED, "G5.1" },
	{ "G1 X1 S1000 F100", 1, 7, MOTION_E_UNSUPPORTED, "'S'" },
	{ "M3", 1, 1, MOTION_E_UNSUPPORTED, "M3" },
	{ "G1 X1.2.3 F100", 1, 4, MOTION_E_NUMBER, "decimal" },
	{ "G1 X F100", 1, 4, MOTION_E_NUMBER, "number" },
	{ "G1 X1 F100\nG1 Y12345678901234567", 2, 4, MOTION_E_NUMBER, "digits" },
	/* zeros between the digits of a fraction (found by tests/fuzz:
	 * multiplied into the mantissa before the digit count was checked,
	 * a signed int64 overflow) */
	{ "G1 X1.50000000000000000004 F100", 1, 4, MOTION_E_NUMBER, "digits" },
	{ "G0 G1 X1", 1, 4, MOTION_E_MODAL, "same modal group" },
	{ "G90 G91", 1, 5, MOTION_E_MODAL, "same modal group" },
	{ "G1 X1 X2 F100", 1, 7, MOTION_E_MODAL, "twice" },
	{ "G1 X10", 1, 1, MOTION_E_MISSING, "feed" },
	{ "G2 X10 Y0 F100", 1, 1, MOTION_E_MISSING, "centre" },
	{ "G2 X10 Y0 I3 J0 F100", 1, 11, MOTION_E_ARC, "not on the arc" },
	{ "G2 X10 R2 F100", 1, 8, MOTION_E_ARC, "too small" },
	{ "G2 R5 F100", 1, 4, MOTION_E_ARC, "end point" },
	{ "G17 G2 X1 K1 F100", 1, 11, MOTION_E_ARC, "plane" },
	{ "G2 X1 I1 R1 F100", 1, 7, MOTION_E_MODAL, "R cannot" },
	{ "G1 X5000 F100", 1, 4, MOTION_E_TRAVEL, "travel" },
	{ "G1 X1 F100\n\nG2 I995 F100", 3, 1, MOTION_E_TRAVEL, "arc leaves" },
	{ "G1 X1 (abc F100", 1, 7, MOTION_E_SYNTAX, "unclosed" },
	{ "G1 X1 (a (b)) F100", 1, 10, MOTION_E_SYNTAX, "nested" },
	{ "G1 X1 # F100", 1, 7, MOTION_E_SYNTAX, "'#'" },
	{ "G1 X1\x01 F100", 1, 6, MOTION_E_SYNTAX, "0x01" },
	{ "G1 A5 F100", 1, 4, MOTION_E_UNSUPPORTED, "not configured" },
	{ "G4", 1, 1, MOTION_E_MISSING, "P" },
	{ "G4 P-1", 1, 4, MOTION_E_NUMBER, "negative" },
	{ "G4 X1 P1", 1, 1, MOTION_E_MODAL, "axis" },
	{ "G1 X1 I2 F100", 1, 7, MOTION_E_MODAL, "'I'" },
	{ "G1 X1 F-5", 1, 7, MOTION_E_NUMBER, "negative" },
	{ "X10", 1, 1, MOTION_E_MISSING, "motion mode" },
	{ "G92", 1, 1, MOTION_E_MISSING, "axis word" },
	{ "G92 G1 X1", 1, 5, MOTION_E_MODAL, "G92" },
	{ "G1 X1 F100 N5", 1, 12, MOTION_E_SYNTAX, "first" },
	{ "G1.5 X1", 1, 1, MOTION_E_UNSUPPORTED, "G1.5" },
	{ "G1 X1 F100 M2 M30", 1, 15, MOTION_E_MODAL, "M-code" },
	{ "G3 I1 P0 F10", 1, 7, MOTION_E_NUMBER, "turns" },
};

static int t_error_classes(void)
{
	int bad = 0;

	for (size_t i = 0; i < sizeof(err_cases) / sizeof(err_cases[0]); i++) {
		const struct err_case *c = &err_cases[i];
		struct motion_error e;
		struct gc_block b;
		struct gc_state st;
		uint32_t l = decode_all(c->prog, &e, &b, &st);
		if (l != c->line || e.line != c->line || e.column != c->col ||
		    e.code != c->code || !strstr(e.msg, c->needle)) {
			printf("  case %zu \"%s\": got line %u col %u code %s msg \"%s\"; want line %u col %u code %s \"%s\"\n",
			       i, c->prog, e.line, e.column, motion_errcode_name(e.code),
			       e.msg, c->line, c->col, motion_errcode_name(c->code),
			       c->needle);
			bad++;
		}
	}
	CHECK(bad == 0, "%d error cases wrong", bad);
	return 0;
}

static int t_error_leaves_state(void)
{
	/* a failing line does not change the modal state or position */
	struct motion_config c = cfg3();
	struct gc_state st;
	struct gc_block b;
	struct motion_error e;

	gc_init(&st, &c);
	CHECK(gc_line(&st, "G1 X1 F100", 10, 1, &b, &e) == 0, "%s", e.msg);
	struct gc_state before = st;
	CHECK(gc_line(&st, "G20 G91 G2 X5 F1", 16, 2, &b, &e) != 0, "should fail");
	CHECK(memcmp(&before, &st, sizeof(st)) == 0, "state changed by a failing line");
	return 0;
}

/* Through the whole pipeline: the error is reported with its line and
 * column, motion before it completes and comes to rest inside the limits,
 * nothing after it runs, and the stream refuses more input. */
static int t_pipeline_error_is_safe(void)
{
	struct motion_config c = cfg3();
	struct trace tr;
	char why[200];
	const char *prog = "G1 X10 F6000\nG1 Y10\nG1 X20 Y20 Q7\nG1 X50\n";

	c.increments_per_mm = 1e6;
	CHECK(run_program(&c, prog, 16, 100000, &tr) == 0, "create");
	CHECK(tr.final == MOTION_ST_FAULT, "final status %d", (int)tr.final);
	CHECK(tr.has_err && tr.err.line == 3 && tr.err.column == 12 &&
		      tr.err.code == MOTION_E_UNSUPPORTED,
	      "error line %u col %u code %s: %s", tr.err.line, tr.err.column,
	      motion_errcode_name(tr.err.code), tr.err.msg);
	const struct motion_setpoint *e = &tr.sp[tr.n - 1];
	CHECK(e->pos[0] == 10000000 && e->pos[1] == 10000000,
	      "stopped at %d,%d, not at the end of line 2", e->pos[0], e->pos[1]);
	CHECK(check_limits(&tr, &c, why, sizeof(why)) == 0, "%s", why);
	trace_free(&tr);

	/* the stream API refuses input in the fault state */
	struct motion *m;
	struct motion_error err;
	struct motion_setpoint sp;
	CHECK(motion_create(&c, &m, &err) == 0, "%s", err.msg);
	CHECK(motion_stream_write(m, "G1 X1 F100\nG7\n", 14) == 14, "write");
	for (int i = 0; i < 2000 && motion_next_setpoint(m, &sp) != MOTION_ST_FAULT; i++)
		;
	CHECK(sp.status == MOTION_ST_FAULT, "no fault");
	CHECK(motion_stream_write(m, "G1 X2\n", 6) == -1, "write accepted after fault");
	CHECK(motion_last_error(m) && motion_last_error(m)->line == 2, "error line");
	motion_destroy(m);
	return 0;
}

static int t_line_too_long(void)
{
	struct motion_config c = cfg3();
	struct trace tr;
	char *prog = malloc(2000);

	CHECK(prog, "oom");
	strcpy(prog, "G1 X1 F100\n(");
	memset(prog + 12, 'a', 600);
	strcpy(prog + 612, ")\nG1 X2\n");
	CHECK(run_program(&c, prog, 100, 100000, &tr) == 0, "create");
	free(prog);
	CHECK(tr.final == MOTION_ST_FAULT && tr.err.code == MOTION_E_LINE_TOO_LONG &&
		      tr.err.line == 2 && tr.err.column == MOTION_MAX_LINE + 1,
	      "got %s line %u col %u", motion_errcode_name(tr.err.code), tr.err.line,
	      tr.err.column);
	CHECK(tr.sp[tr.n - 1].pos[0] == 1000, "did not finish line 1");
	trace_free(&tr);
	return 0;
}

static int t_after_m2_ignored(void)
{
	struct motion_config c = cfg3();
	struct trace tr;

	CHECK(run_program(&c, "G1 X1 F600\nM2\nG1 X5\nthis is not G-code\n", 8,
			  100000, &tr) == 0, "create");
	CHECK(tr.final == MOTION_ST_DONE && !tr.has_err, "status %d", (int)tr.final);
	CHECK(tr.sp[tr.n - 1].pos[0] == 1000, "ran past M2");
	CHECK(tr.stats.ignored_lines == 2, "ignored %llu lines",
	      (unsigned long long)tr.stats.ignored_lines);
	trace_free(&tr);
	return 0;
}

static int t_fuzz_never_crashes(void)
{
	/* random G-code-like lines: every run ends DONE or FAULT at rest,
	 * inside the limits */
	static const char alpha[] = "GGGMXYZIJKRFPN0123456789..-+ ()\t;XYZ%abQ#";
	struct motion_config c = cfg3();
	uint32_t s = 99;
	char why[200];
	int faults = 0;

	c.increments_per_mm = 1e4;
	for (int run = 0; run < 60; run++) {
		char prog[4096];
		size_t len = 0;
		len += (size_t)snprintf(prog, sizeof(prog), "G1 X1 F3000\n");
		for (int l = 0; l < 30; l++) {
			int n = (int)((s = s * 1103515245u + 12345u) >> 16) % 24;
			for (int i = 0; i < n && len < sizeof(prog) - 2; i++) {
				s = s * 1103515245u + 12345u;
				prog[len++] = alpha[(s >> 16) % (sizeof(alpha) - 1)];
			}
			prog[len++] = '\n';
		}
		prog[len] = 0;
		struct trace tr;
		CHECK(run_program(&c, prog, 37, 2000000, &tr) == 0, "create");
		CHECK(tr.final == MOTION_ST_DONE || tr.final == MOTION_ST_FAULT,
		      "run %d ended with %d", run, (int)tr.final);
		if (tr.final == MOTION_ST_FAULT) {
			faults++;
			CHECK(tr.err.line >= 2 && tr.err.column >= 1 && tr.err.msg[0],
			      "fault without a position: line %u col %u", tr.err.line,
			      tr.err.column);
		}
		CHECK(check_limits(&tr, &c, why, sizeof(why)) == 0, "run %d: %s", run, why);
		trace_free(&tr);
	}
	CHECK(faults > 30, "only %d of 60 random programs failed", faults);
	return 0;
}

static const struct test_case cases[] = {
	{ "decode_basic", t_decode_basic },
	{ "error_classes", t_error_classes },
	{ "error_leaves_state", t_error_leaves_state },
	{ "pipeline_error_is_safe", t_pipeline_error_is_safe },
	{ "line_too_long", t_line_too_long },
	{ "after_m2_ignored", t_after_m2_ignored },
	{ "fuzz_never_crashes", t_fuzz_never_crashes },
};

int main(int argc, char **argv)
{
	return test_main(argc, argv, cases, sizeof(cases) / sizeof(cases[0]));
}
