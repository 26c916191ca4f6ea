// SPDX-License-Identifier: MIT
/* params.c - the parameter set: text forms, the file, the servo, the
 * "param" request (params.h). */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "context.h"

const struct sp_param_desc param_desc[SP_P_COUNT] = SP_PARAM_TABLE_INIT;

/* ---- text forms --------------------------------------------------------- */

static int param_by_name(const char *s)
{
	char *end;
	unsigned long id;

	for (int i = 0; i < SP_P_COUNT; i++)
		if (!strcmp(param_desc[i].name, s))
			return i;
	id = strtoul(s, &end, 0);
	if (*s && !*end && id < SP_P_COUNT)
		return (int)id;
	return -1;
}

static double param_double(const struct sp_param_desc *d, uint32_t w)
{
	switch (d->type) {
	case SP_T_F32: return (double)sp_f32_from_word(w);
	case SP_T_I32: return (double)(int32_t)w;
	default: return (double)w;
	}
}

static void fmt_value(const struct sp_param_desc *d, uint32_t w, char *buf, size_t n)
{
	switch (d->type) {
	case SP_T_F32: snprintf(buf, n, "%.9g", (double)sp_f32_from_word(w)); break;
	case SP_T_I32: snprintf(buf, n, "%d", (int32_t)w); break;
	default: snprintf(buf, n, "%u", w); break;
	}
}

static void fmt_num(const struct sp_param_desc *d, double v, char *buf, size_t n)
{
	if (d->type == SP_T_F32)
		snprintf(buf, n, "%.9g", (double)(float)v);
	else
		snprintf(buf, n, "%.0f", v);
}

/* Is w a value of d's type within its documented range? (NaN and the
 * infinities are not.) */
static int value_in_range(const struct sp_param_desc *d, uint32_t w)
{
	double v;

	if (d->type == SP_T_F32) {
		float f = sp_f32_from_word(w);

		return !isnan(f) && f >= (float)d->min && f <= (float)d->max;
	}
	v = d->type == SP_T_I32 ? (double)(int32_t)w : (double)w;
	return v >= d->min && v <= d->max;
}

/* Parse and range-check a value: SE_OK and *w, or SE_VALUE with a message. */
static int parse_value(const struct servod *sd, const struct sp_param_desc *d, const char *s, uint32_t *w,
		       char *msg, size_t n)
{
	char *end, lo[32], hi[32];
	int ok = 1;

	fmt_num(d, d->min, lo, sizeof(lo));
	fmt_num(d, d->max, hi, sizeof(hi));
	errno = 0;
	if (d->type == SP_T_F32) {
		float f = strtof(s, &end);

		if (!*s || *end || errno || isnan(f))
			ok = -1;
		else if (f < (float)d->min || f > (float)d->max)
			ok = 0;
		*w = sp_word_from_f32(f);
	} else {
		long long v = strtoll(s, &end, 0);

		if (!*s || *end || errno)
			ok = -1;
		else if (v < (long long)d->min || v > (long long)d->max)
			ok = 0;
		*w = d->type == SP_T_I32 ? (uint32_t)(int32_t)v : (uint32_t)v;
	}
	if (ok < 0) {
		snprintf(msg, n, "%s: '%s' is not a%s %s", d->name, s,
			 d->type == SP_T_F32 ? "" : "n", d->type == SP_T_F32 ? "number" : "integer");
		return SE_VALUE;
	}
	if (!ok) {
		snprintf(msg, n, "%s: %s out of range [%s, %s]%s%s", d->name, s, lo, hi,
			 *d->unit ? " " : "", d->unit);
		return SE_VALUE;
	}
	if ((d->flags & SP_F_RO) && *w != sd->pset[d->id]) {
		snprintf(msg, n, "%s is read-only", d->name);
		return SE_VALUE;
	}
	return SE_OK;
}

/* ---- the file --------------------------------------------------------------- */

static void params_defaults(struct servod *sd)
{
	for (int i = 0; i < SP_P_COUNT; i++) {
		const struct sp_param_desc *d = &param_desc[i];

		sd->pset[i] = d->type == SP_T_F32 ? sp_word_from_f32((float)d->def) :
			      d->type == SP_T_I32 ? (uint32_t)(int32_t)d->def : (uint32_t)d->def;
	}
}

void params_load(struct servod *sd)
{
	const char *path = sd->opt.param_path;
	FILE *f = fopen(path, "r");
	char line[256], name[64], val[64], msg[160];
	int n = 0;

	params_defaults(sd);
	if (!f) {
		logm(sd, "no parameter file %s: defaults", path);
		return;
	}
	while (fgets(line, sizeof(line), f)) {
		int id;
		uint32_t w;

		if (line[0] == '#' || sscanf(line, "%63s %63s", name, val) != 2)
			continue;
		id = param_by_name(name);
		if (id < 0) {
			logm(sd, "%s: unknown parameter '%s' ignored", path, name);
			continue;
		}
		if (parse_value(sd, &param_desc[id], val, &w, msg, sizeof(msg)) != SE_OK) {
			logm(sd, "%s: %s (default kept)", path, msg);
			continue;
		}
		sd->pset[id] = w;
		n++;
	}
	fclose(f);
	logm(sd, "loaded %d parameter(s) from %s", n, path);
}

/*
 * write temp + fsync + rename + fsync(dir): 0, or the errno of the step that
 * failed. A failure leaves the file as it was (the temp file is removed).
 */
static int params_save(const struct servod *sd)
{
	const char *path = sd->opt.param_path;
	char tmp[300], dir[300], v[48];
	FILE *f;
	int fd, err;
	char *slash;

	snprintf(dir, sizeof(dir), "%s", path);
	slash = strrchr(dir, '/');
	if (slash && slash != dir) {
		*slash = 0;
		mkdir(dir, 0755);
	} else {
		snprintf(dir, sizeof(dir), ".");
	}
	snprintf(tmp, sizeof(tmp), "%s.tmp", path);
	f = fopen(tmp, "w");
	if (!f)
		return errno;
	errno = 0;
	fprintf(f, "# servod parameter set (servoamp/servo_proto.h); loaded into the servo at every attach\n");
	for (int i = 0; i < SP_P_COUNT; i++) {
		if (!(param_desc[i].flags & SP_F_RESTORE))
			continue;
		fmt_value(&param_desc[i], sd->pset[i], v, sizeof(v));
		fprintf(f, "%s %s\n", param_desc[i].name, v);
	}
	if (fflush(f) || ferror(f) || fsync(fileno(f))) {
		err = errno ? errno : EIO;
		fclose(f);
		unlink(tmp);
		return err;
	}
	if (fclose(f) || rename(tmp, path)) {
		err = errno;
		unlink(tmp);
		return err;
	}
	fd = open(dir, O_RDONLY | O_DIRECTORY);
	if (fd >= 0) {
		fsync(fd);
		close(fd);
	}
	return 0;
}

/* ---- the servo -------------------------------------------------------------- */

/*
 * servod's whole set to the servo in one SP_CMD_PARAM_SET_MANY: SE_OK, or
 * SE_* with a message. *refused: the servo answered with an error status,
 * so it applied none of it (the request is checked whole before any of it
 * is applied); otherwise, on an error, what it holds is unknown. SE_OK
 * ends a pending re-send (session.params_resend).
 */
static int send_set(struct servod *sd, int *refused, char *msg, size_t n)
{
	uint32_t req[1 + 2 * SP_P_COUNT], resp[4] = { 0 }, cnt = 0, len = 0;
	int32_t status;
	int rc;

	*refused = 0;
	for (int i = 0; i < SP_P_COUNT; i++) {
		if (!(param_desc[i].flags & SP_F_RESTORE))
			continue;
		req[1 + 2 * cnt] = (uint32_t)i;
		req[2 + 2 * cnt] = sd->pset[i];
		cnt++;
	}
	req[0] = cnt;
	rc = mbox_request(sd, SP_CMD_PARAM_SET_MANY, req, 4u * (1u + 2u * cnt), resp, sizeof(resp), &len, &status,
			  msg, n);
	if (rc == SE_OK && status) {
		snprintf(msg, n, "servo refused the parameter set: %s", sp_strerror(status));
		*refused = 1;
		rc = SE_SERVO;
	} else if (rc == SE_OK && (len != 4 || resp[0] != cnt)) {
		/* the answer is {n}: checked like input from the network */
		char count[24] = "";

		if (len >= 4)
			snprintf(count, sizeof(count), ", count %u", resp[0]);
		snprintf(msg, n, "servo answered the parameter set of %u with %u byte(s)%s: refused", cnt, len, count);
		rc = SE_SERVO;
	} else if (rc == SE_OK) {
		sd->session.params_resend = 0;	/* the servo has servod's set */
		sd->session.resend_tries = 0;
	}
	return rc;
}

int params_restore(struct servod *sd, char *msg, size_t n)
{
	int refused;

	return send_set(sd, &refused, msg, n);
}

void params_resend(struct servod *sd)
{
	struct session *ss = &sd->session;
	uint32_t tries = ss->resend_tries;
	uint64_t now = mono_now_ns();
	char msg[256];

	if (!ss->params_resend || (tries && now - ss->resend_ns < 1000000000ull))
		return;
	ss->resend_ns = now;
	if (params_restore(sd, msg, sizeof(msg)) == SE_OK) {
		logm(sd, "servod's parameter set sent again: the servo has it (try %u)", tries + 1u);
		return;
	}
	if (!ss->resend_tries++)
		logw(sd, "sending servod's parameter set again failed (%s): trying every second", msg);
}

/* What servod itself follows of a new value: the period, the watchdog, the axes. */
static void apply_local(struct servod *sd, uint32_t id, uint32_t w)
{
	pthread_mutex_lock(&sd->lock);
	if (id == SP_P_cycle_period_us)
		sd->period_ns = w * 1000u;
	else if (id == SP_P_wd_limit)
		(void)amp_linux_set_wd_limit(&sd->amp, w);
	else if (id == SP_P_axes)
		sd->axes = w;
	pthread_mutex_unlock(&sd->lock);
}

void params_publish(struct servod *sd, uint32_t id, uint32_t w)
{
	const struct sp_param_desc *d = &param_desc[id];

	if (sd->telem_on)
		telem_push_param(&sd->telem, 0, id, d->name, d->type, param_double(d, w), d->unit);
}

/* ---- "param list | param get NAME | param set NAME VALUE" ----------------- */

static void param_list(const struct servod *sd, struct out *o)
{
	char v[48], lo[32], hi[32], df[32];

	put(o, "%-3s %-16s %-4s %-10s %-12s %-12s %-12s %s\n", "id", "name", "type", "unit", "min", "max",
	    "default", "value");
	for (int i = 0; i < SP_P_COUNT; i++) {
		const struct sp_param_desc *d = &param_desc[i];

		fmt_value(d, sd->pset[i], v, sizeof(v));
		fmt_num(d, d->min, lo, sizeof(lo));
		fmt_num(d, d->max, hi, sizeof(hi));
		fmt_num(d, d->def, df, sizeof(df));
		put(o, "%-3u %-16s %-4s %-10s %-12s %-12s %-12s %s%s\n", d->id, d->name,
		    d->type == SP_T_F32 ? "f32" : d->type == SP_T_I32 ? "i32" : "u32",
		    *d->unit ? d->unit : "-", lo, hi, df, v, (d->flags & SP_F_RO) ? " (ro)" : "");
	}
}

static void put_value(struct out *o, const struct sp_param_desc *d, uint32_t w)
{
	char v[48];

	fmt_value(d, w, v, sizeof(v));
	put(o, "%s=%s%s%s\n", d->name, v, *d->unit ? " " : "", d->unit);
}

/*
 * The servo's answer {id, value} to "param get|set" of id, checked like
 * input from the network before anything uses it: its length, the id
 * asked for, a value of the parameter's type within its documented range
 * (a read-only one: the value servod knows). SE_OK, or SE_SERVO with the
 * reason in msg and in servod's log; the value then becomes nothing of
 * servod's (not its set, its file, its period, watchdog or axis count).
 */
static int check_answer(struct servod *sd, const char *op, int id, uint32_t len, const uint32_t *resp, char *msg,
			size_t n)
{
	const struct sp_param_desc *d = &param_desc[id];
	char v[48], lo[32], hi[32], have[48];

	if (len != 8) {
		snprintf(msg, n, "%s %s: the servo answered %u byte(s), expected 8: refused", op, d->name, len);
	} else if (resp[0] != (uint32_t)id) {
		snprintf(msg, n, "%s %s: the servo answered for parameter id %u: refused", op, d->name, resp[0]);
	} else if (!value_in_range(d, resp[1])) {
		fmt_value(d, resp[1], v, sizeof(v));
		fmt_num(d, d->min, lo, sizeof(lo));
		fmt_num(d, d->max, hi, sizeof(hi));
		snprintf(msg, n, "%s %s: the servo answered %s (0x%08x), outside the range [%s, %s]%s%s: refused", op,
			 d->name, v, resp[1], lo, hi, *d->unit ? " " : "", d->unit);
	} else if ((d->flags & SP_F_RO) && resp[1] != sd->pset[id]) {
		fmt_value(d, resp[1], v, sizeof(v));
		fmt_value(d, sd->pset[id], have, sizeof(have));
		snprintf(msg, n, "%s %s: the servo answered %s for a read-only parameter that is %s: refused", op,
			 d->name, v, have);
	} else {
		return SE_OK;
	}
	fmt_value(d, sd->pset[id], have, sizeof(have));
	logw(sd, "%s (servod keeps %s=%s)", msg, d->name, have);
	return SE_SERVO;
}

static int param_get(struct servod *sd, struct out *o, int id, char *msg, size_t n)
{
	uint32_t req[1] = { (uint32_t)id }, resp[2] = { 0, 0 }, len = 0;
	int32_t status;
	int rc = mbox_request(sd, SP_CMD_PARAM_GET, req, 4, resp, sizeof(resp), &len, &status, msg, n);

	if (rc)
		return rc;
	if (status) {
		snprintf(msg, n, "%s: %s", param_desc[id].name, sp_strerror(status));
		return SE_SERVO;
	}
	rc = check_answer(sd, "get", id, len, resp, msg, n);
	if (rc)
		return rc;
	put_value(o, &param_desc[id], resp[1]);
	return SE_OK;
}

/*
 * The servo took d = w, but servod could not store its set (err). A set is
 * all or nothing: servod's set (the file's, d unchanged) goes back to the
 * servo, so that what the servo uses (`param get`), what servod follows
 * (its set, period, watchdog, axes) and the file agree again. A servo that
 * refuses it (an error status: it applied none of it, it still uses w) is
 * followed by servod, and the message says that the file differs. Without
 * a usable answer the servo's values are unknown: servod keeps its set and
 * sends it again (params_resend) until the servo takes it. SE_IO.
 */
static int save_failed(struct servod *sd, const struct sp_param_desc *d, uint32_t w, int err, char *msg, size_t n)
{
	const char *path = sd->opt.param_path;
	char why[160], was[48], now[48];
	int refused;

	fmt_value(d, sd->pset[d->id], was, sizeof(was));
	fmt_value(d, w, now, sizeof(now));
	if (send_set(sd, &refused, why, sizeof(why)) == SE_OK) {
		snprintf(msg, n, "cannot store %s: %s; the servo set back to %s=%s: nothing changed", path,
			 strerror(err), d->name, was);
	} else if (refused) {
		sd->pset[d->id] = w;
		apply_local(sd, d->id, w);
		params_publish(sd, d->id, w);
		snprintf(msg, n, "cannot store %s: %s; the servo refused to go back to %s=%s (%s): the servo and "
			 "servod use %s=%s, the file still says %s", path, strerror(err), d->name, was, why, d->name, now,
			 was);
	} else {
		sd->session.params_resend = 1;
		snprintf(msg, n, "cannot store %s: %s; setting the servo back to %s=%s failed (%s): servod and the file "
			 "say %s=%s, the servo may use %s until servod's set reaches it (sent again every second)", path,
			 strerror(err), d->name, was, why, d->name, was, now);
	}
	logw(sd, "param set %s %s: %s", d->name, now, msg);
	return SE_IO;
}

static int param_set(struct servod *sd, struct out *o, int id, const char *value, char *msg, size_t n)
{
	const struct sp_param_desc *d = &param_desc[id];
	uint32_t req[2], resp[2] = { 0, 0 }, len = 0, w;
	int32_t status;
	int rc = parse_value(sd, d, value, &w, msg, n);

	if (rc)
		return rc;
	req[0] = (uint32_t)id;
	req[1] = w;
	rc = mbox_request(sd, SP_CMD_PARAM_SET, req, 8, resp, sizeof(resp), &len, &status, msg, n);
	if (rc)
		return rc;
	if (status) {
		snprintf(msg, n, "%s: %s", d->name, sp_strerror(status));
		return status == SP_E_RANGE || status == SP_E_READONLY || status == SP_E_OVERLOAD ? SE_VALUE : SE_SERVO;
	}
	rc = check_answer(sd, "set", id, len, resp, msg, n);
	if (rc) {
		/* The servo took the request and answered nonsense: whatever it
		 * holds now is unknown. Put servod's parameter set back on it
		 * (the one at the last attach, with this parameter unchanged). */
		char why[160];
		size_t used = strlen(msg);

		if (params_restore(sd, why, sizeof(why)) == SE_OK) {
			snprintf(msg + used, n - used, "; servod's parameter set sent again (%s unchanged)", d->name);
		} else {
			sd->session.params_resend = 1;
			snprintf(msg + used, n - used, "; sending servod's parameter set again failed (%s): "
				 "servod sends it again every second until the servo takes it", why);
		}
		return rc;
	}
	if (d->flags & SP_F_RESTORE) {
		uint32_t old = sd->pset[id];
		int err;

		sd->pset[id] = resp[1];
		err = params_save(sd);
		if (err) {
			sd->pset[id] = old;
			return save_failed(sd, d, resp[1], err, msg, n);
		}
	}
	apply_local(sd, (uint32_t)id, resp[1]);
	params_publish(sd, (uint32_t)id, resp[1]);
	put_value(o, d, resp[1]);
	return SE_OK;
}

static int req_param(struct servod *sd, struct out *o, int argc, char **argv, char *msg, size_t n)
{
	int id;

	argc--, argv++;
	if (argc >= 1 && !strcmp(argv[0], "list")) {
		param_list(sd, o);
		return SE_OK;
	}
	if (argc < 2 || (strcmp(argv[0], "get") && strcmp(argv[0], "set")) ||
	    (!strcmp(argv[0], "set") && argc != 3) || (!strcmp(argv[0], "get") && argc != 2)) {
		snprintf(msg, n, "usage: param list | param get NAME | param set NAME VALUE");
		return SE_USAGE;
	}
	id = param_by_name(argv[1]);
	if (id < 0) {
		snprintf(msg, n, "unknown parameter '%s' (see: ampctl param list)", argv[1]);
		return SE_UNKNOWN;
	}
	if (!strcmp(argv[0], "get"))
		return param_get(sd, o, id, msg, n);
	return param_set(sd, o, id, argv[2], msg, n);
}
SERVOD_REQUEST("param", req_param);
