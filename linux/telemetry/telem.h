/* SPDX-License-Identifier: MIT */
/*
 * telem.h - servoamp telemetry transport: every cycle on record.
 *
 * The real-time cycle thread pushes one fixed-size record per cycle into a
 * lock-free single-producer / single-consumer ring (telem_push_cycle: no
 * syscall, no lock, no allocation, never waits: when the ring is full the
 * record is dropped and counted). A non-real-time drain thread streams the
 * records, plus parameter changes, firmware log lines, gaps, queue levels
 * and statistics pushed from other threads, to every connected TCP client
 * in the wire format of docs/telemetry.md (version TELEM_WIRE_VERSION).
 *
 *   struct telem t;
 *   struct telem_cfg cfg;
 *   telem_cfg_defaults(&cfg);          // 127.0.0.1:7700, ring 4096, ...
 *   cfg.n_axes = 4; cfg.cycle_period_ns = 1000000; cfg.clock_hz = ...;
 *   telem_init(&t, &cfg);              // allocates, binds, listens
 *   telem_start(&t);                   // starts the drain thread
 *   ... cycle thread: telem_push_cycle(&t, &rec);
 *   ... other threads: telem_push_param / _log / _gap / _queues
 *   telem_stop(&t);                    // drains, final STATS, closes clients
 *   telem_destroy(&t);
 *
 * Records and counters use C11 atomics only (lock-free on x86-64 and
 * ARMv7-A with LDREXD/STREXD, checked at compile time).
 */
#ifndef SERVOAMP_TELEM_H
#define SERVOAMP_TELEM_H

#include <pthread.h>
#include <stdatomic.h>
#include <stddef.h>
#include <stdint.h>

#include "amp/amp_ocm_layout.h"	/* struct amp_cmd_axis, amp_fb_axis, AMP_MAX_AXES */
#include "motion/ring.h"		/* the repository's SPSC ring */

#define TELEM_WIRE_VERSION 1u
#define TELEM_MAGIC 0x4d4c5453u		/* "STLM" little-endian */
#define TELEM_DEFAULT_PORT 7700u
#define TELEM_MAX_CLIENTS 8u
#define TELEM_MAX_COUNTERS 16u
#define TELEM_SNAPSHOT_TRIES 64u	/* STATS: reads of the app's counters for one snapshot (app_seq) */
#define TELEM_MAX_QUEUES 8u
#define TELEM_LOG_MAX 480u		/* bytes of text in one LOG message */
#define TELEM_NAME_LEN 32u		/* PARAM name */
#define TELEM_UNIT_LEN 16u		/* PARAM unit */
#define TELEM_SOURCE_LEN 16u		/* LOG source */
#define TELEM_COUNTER_NAME_LEN 24u
#define TELEM_QUEUE_NAME_LEN 16u
#define TELEM_ID_LEN 32u		/* controller id in HELLO */
#define TELEM_TOKEN_MAX 64u		/* bytes of the shared token in AUTH */

/* Message types on the wire (frame header "type"). */
enum telem_msg_type {
	TELEM_MSG_HELLO = 1,
	TELEM_MSG_CYCLE = 2,
	TELEM_MSG_STATS = 3,
	TELEM_MSG_PARAM = 4,
	TELEM_MSG_LOG = 5,
	TELEM_MSG_GAP = 6,
	TELEM_MSG_QUEUES = 7,
	TELEM_MSG_AUTH = 8,	/* client -> server, the first client frame */
	TELEM_MSG_REQUEST = 9,	/* client -> server after AUTH: u32 id, text (cfg.requests) */
	TELEM_MSG_REPLY = 10,	/* server -> the client that asked: u32 id, i32 status, u32 n, text */
};

/* Requests (docs/telemetry.md "Requests"): an authenticated client may send
 * REQUEST frames; the application takes them with telem_pop_request (any
 * thread) and answers with telem_reply. */
#define TELEM_REQ_MAX 256u		/* request text bytes */
#define TELEM_REPLY_MAX 4000u		/* reply text bytes */
#define TELEM_REQ_PER_CLIENT 2u		/* requests of one client in flight */
#define TELEM_REPLY_BUSY (-1)		/* status: too many requests in flight */
#define TELEM_REPLY_UNSERVED (-2)	/* status: this server takes no requests */

struct telem_request {
	uint32_t slot;			/* the client (opaque to the application) */
	uint64_t conn;
	uint32_t id;			/* the client's request id, echoed in the reply */
	uint32_t len;			/* text bytes */
	char text[TELEM_REQ_MAX + 1];	/* NUL-terminated (a NUL inside ends it early) */
};

/* Exchange status of a cycle: the same values as amp_lib's enum amp_rx_status. */
enum telem_exchange {
	TELEM_X_FRESH = 0,
	TELEM_X_STALE = 1,
	TELEM_X_TORN = 2,
	TELEM_X_MISSED = 3,
	TELEM_X_INVALID = 4,
	TELEM_X_NONE = 5,	/* no exchange this cycle (servo absent, stalled) */
};

/* GAP reasons. */
enum telem_gap_reason {
	TELEM_GAP_RING_OVERFLOW = 1,	/* ring full: the cycle thread dropped records */
	TELEM_GAP_CLIENT_OVERFLOW = 2,	/* this client read too slowly: records not sent to it */
	TELEM_GAP_CONTROLLER_RESTART = 3,	/* servo re-attached / restarted (new attach, new epoch) */
	TELEM_GAP_RECOVERY = 4,		/* remoteproc recovery after a stall or crash */
	TELEM_GAP_OTHER = 5,
};

/* Log levels: the values of foxglove.LogLevel. */
enum telem_log_level {
	TELEM_LOG_UNKNOWN = 0,
	TELEM_LOG_DEBUG = 1,
	TELEM_LOG_INFO = 2,
	TELEM_LOG_WARNING = 3,
	TELEM_LOG_ERROR = 4,
	TELEM_LOG_FATAL = 5,
};

/* Parameter value types (as servo_proto.h's enum sp_type, plus f64). */
enum telem_param_type {
	TELEM_P_U32 = 0,
	TELEM_P_I32 = 1,
	TELEM_P_F32 = 2,
	TELEM_P_F64 = 3,
};

/* One cycle, filled by the cycle thread (the caller), copied into the ring. */
struct telem_cycle {
	uint64_t cycle;			/* controller (servod) cycle counter */
	uint64_t t_ns;			/* controller CLOCK_MONOTONIC, ns (wake-up) */
	uint32_t servo_cycle;		/* feedback record: servo cycle counter */
	uint32_t t_cycle;		/* feedback record: servo ticks at cycle start */
	uint32_t irq_latency;		/* feedback record: servo ticks, irq to handler */
	uint32_t wake_latency_ns;	/* servod: interrupt to cycle thread running */
	uint32_t exchange;		/* enum telem_exchange (amp_rx_info.status) */
	uint32_t missed;		/* amp_rx_info.missed */
	uint32_t servo_status;		/* feedback record: servo state word */
	int32_t result;			/* amp_linux_cycle() return code */
	uint32_t n_axes;		/* <= AMP_MAX_AXES; the HELLO's axis count is sent */
	struct amp_cmd_axis cmd[AMP_MAX_AXES];
	struct amp_fb_axis fb[AMP_MAX_AXES];
};

/* A named counter for STATS (application counters, e.g. servod's). */
struct telem_counter {
	char name[TELEM_COUNTER_NAME_LEN];
	uint64_t value;
};

/* A queue level for QUEUES (motion pipeline). */
struct telem_queue_level {
	char name[TELEM_QUEUE_NAME_LEN];
	uint32_t level;
	uint32_t capacity;
};

struct telem_cfg {
	const char *listen_addr;	/* numeric address, "127.0.0.1" default, "::1" ok */
	uint16_t port;			/* 0: any free port (see telem_port) */
	const char *controller_id;	/* HELLO, <= 31 bytes used */
	uint32_t n_axes;		/* axes sent per CYCLE, 1..AMP_MAX_AXES */
	uint32_t cycle_period_ns;
	uint32_t clock_hz;		/* rate of t_cycle / irq_latency ticks */
	uint32_t ring_capacity;		/* records, power of two >= 2 */
	uint32_t event_capacity;	/* PARAM/LOG/GAP/QUEUES queued, >= 1 */
	uint32_t client_buffer;		/* bytes buffered per client */
	uint32_t max_clients;		/* <= TELEM_MAX_CLIENTS */
	uint32_t drain_interval_us;	/* drain thread period */
	uint32_t stats_interval_ms;	/* STATS every ... (0: only the final one) */
	uint32_t linger_ms;		/* telem_stop: time to flush clients */
	/* Who may connect. Every client must send one AUTH frame within
	 * auth_timeout_ms of connecting; until then it gets nothing and its slot
	 * may be taken by a newer connection. With a token (token_len 1..
	 * TELEM_TOKEN_MAX bytes, copied) the AUTH payload must equal it; a wrong
	 * or malformed AUTH closes the connection. Without one (NULL) any AUTH
	 * payload is accepted. */
	const void *token;
	uint32_t token_len;
	uint32_t auth_timeout_ms;	/* default 2000 */
	uint32_t stall_timeout_ms;	/* a client whose socket takes no byte for this long is dropped; default 10000 */
	int mlock;			/* lock the ring in memory (mlock) */
	int requests;			/* 1: queue REQUEST frames for telem_pop_request */
	/* Called from the drain thread for each STATS message: fill up to max
	 * application counters, return how many. May be NULL. */
	unsigned (*app_counters)(void *arg, struct telem_counter *out, unsigned max);
	/* Optional, with app_counters: the application's seqcount, odd while
	 * it pushes a cycle and changes its counters, even between. Every
	 * access is seq_cst (no fences: ThreadSanitizer has none): the
	 * application stores the odd value, pushes and stores its counters,
	 * stores the even value; app_counters and this load them; the pushed
	 * and dropped totals are stored and loaded seq_cst too. With it a
	 * STATS message's counters and its pushed/dropped totals are one
	 * snapshot between two cycles: the drain thread reads again while the
	 * count is odd or moved (up to TELEM_SNAPSHOT_TRIES times, 20 us
	 * apart, then sends what it read). May be NULL. */
	uint64_t (*app_seq)(void *arg);
	void *app_arg;
};

/* Totals, readable from any thread (telem_get_stats). */
struct telem_stats {
	uint64_t pushed;		/* telem_push_cycle calls */
	uint64_t dropped;		/* of which dropped: ring full */
	uint64_t drained;		/* records taken out of the ring */
	uint64_t events;		/* PARAM/LOG/GAP/QUEUES accepted */
	uint64_t events_dropped;	/* event queue full */
	uint64_t client_lost;		/* records not sent to slow clients (all clients) */
	uint64_t bytes_sent;
	uint64_t clients_total;		/* connections accepted */
	uint32_t clients;		/* connected now (authenticated) */
	uint32_t ring_high_water;
	/* connections closed by the server, by reason */
	uint64_t auth_failed;		/* wrong token or malformed AUTH */
	uint64_t auth_timeout;		/* no AUTH within auth_timeout_ms */
	uint64_t evicted;		/* not yet authenticated, slot given to a newer connection */
	uint64_t refused;		/* every slot held by authenticated clients */
	uint64_t stalled;		/* socket took no byte for stall_timeout_ms */
	uint64_t protocol;		/* sent more than AUTH (flooding) */
};

/* ---- the transport -------------------------------------------------------- */
struct telem_client;
struct telem_event;
struct telem_reply;

struct telem {
	struct telem_cfg cfg;
	char controller_id[TELEM_ID_LEN];
	uint64_t session_id;
	struct ring ring;		/* the cycle records (struct telem_slot), motion/ring.h */
	/* producer-only state, published with relaxed stores */
	uint64_t push_seq;		/* producer-local */
	uint64_t drop_local;		/* producer-local */
	_Atomic uint64_t pushed;
	_Atomic uint64_t dropped;
	_Atomic uint64_t last_cycle;	/* last cycle pushed (for events) */
	/* drain-thread state */
	_Atomic uint64_t drained;
	_Atomic uint64_t client_lost;
	_Atomic uint64_t bytes_sent;
	_Atomic uint64_t clients_total;
	_Atomic uint32_t clients_now;
	_Atomic uint32_t ring_high_water;
	_Atomic uint64_t drop_auth_failed, drop_auth_timeout, drop_evicted, drop_refused,
		drop_stalled, drop_protocol;
	unsigned char token[TELEM_TOKEN_MAX];
	uint64_t expect_seq;
	uint64_t prev_cycle;
	int have_prev;
	/* events (non-RT producers): a mutex-protected queue of encoded frames */
	pthread_mutex_t ev_lock;
	struct telem_event *ev;
	uint32_t ev_head, ev_tail, ev_cap;
	_Atomic uint64_t events;
	_Atomic uint64_t events_dropped;
	/* requests and replies (under ev_lock) */
	struct telem_request *req;
	uint32_t req_head, req_tail;
	struct telem_reply *rep;
	uint32_t rep_head, rep_tail;
	/* network */
	int listen_fd;
	int wake_fd[2];
	uint16_t port;
	struct telem_client *clients;
	unsigned char *scratch;		/* encoding buffer for one drain batch */
	size_t scratch_cap;
	pthread_t thread;
	_Atomic int running;
	int started;
};

void telem_cfg_defaults(struct telem_cfg *cfg);
/* 0, or -errno (EINVAL for a bad configuration). Binds and listens. */
int telem_init(struct telem *t, const struct telem_cfg *cfg);
int telem_start(struct telem *t);
/* Stops the drain thread after a last drain, a final STATS and up to
 * linger_ms of flushing; closes every client. */
void telem_stop(struct telem *t);
void telem_destroy(struct telem *t);
uint16_t telem_port(const struct telem *t);

/* Real-time safe: no syscall, no lock, no allocation, never waits.
 * Returns 0, or -1 when the ring was full (the record is dropped and counted). */
int telem_push_cycle(struct telem *t, const struct telem_cycle *rec);

/* Non-real-time producers (any thread). t_ns 0 = now (CLOCK_MONOTONIC).
 * 0, or -1 when the event queue is full (dropped and counted). */
int telem_push_param(struct telem *t, uint64_t t_ns, uint32_t id, const char *name,
		     uint32_t type, double value, const char *unit);
int telem_push_log(struct telem *t, uint64_t t_ns, uint32_t level, const char *source,
		   const char *text, size_t len);
int telem_push_gap(struct telem *t, uint64_t t_ns, uint64_t from_cycle, uint64_t to_cycle,
		   uint64_t count, uint32_t reason);
int telem_push_queues(struct telem *t, uint64_t t_ns, const struct telem_queue_level *q,
		      unsigned n);

void telem_get_stats(struct telem *t, struct telem_stats *st);

/* Requests (cfg.requests): 1 and *r when one is waiting, else 0. Any thread. */
int telem_pop_request(struct telem *t, struct telem_request *r);
/* The answer to r (status 0 ok, else the application's error code; text
 * truncated to TELEM_REPLY_MAX). Sent to r's client if it is still the same
 * connection. 0, or -1 when the reply queue is full. Any thread. */
int telem_reply(struct telem *t, const struct telem_request *r, int32_t status, const char *text,
		size_t len);

#endif /* SERVOAMP_TELEM_H */
