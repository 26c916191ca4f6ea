/* Minimal test harness for the host C tests: CHECK() records failures and
 * keeps going; check_summary() prints the totals and returns the exit code. */
#ifndef CHECK_H
#define CHECK_H

#include <stdio.h>

static unsigned check_pass, check_fail;

#define CHECK(cond) do { \
	if (cond) { check_pass++; } else { check_fail++; \
		fprintf(stderr, "%s:%d: CHECK failed: %s\n", __FILE__, __LINE__, #cond); } \
} while (0)

#define CHECK_EQ(a, b) do { \
	long long va_ = (long long)(a), vb_ = (long long)(b); \
	if (va_ == vb_) { check_pass++; } else { check_fail++; \
		fprintf(stderr, "%s:%d: CHECK_EQ failed: %s == %lld, %s == %lld\n", \
			__FILE__, __LINE__, #a, va_, #b, vb_); } \
} while (0)

static inline int check_summary(const char *name)
{
	printf("%s: %u checks passed, %u failed\n", name, check_pass, check_fail);
	return check_fail ? 1 : 0;
}

#endif
