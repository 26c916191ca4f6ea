/* SPDX-License-Identifier: MIT */
/*
 * amp_ocm_layout.h - THE on-chip-memory layout shared by Linux and the
 * servo core. Everything that crosses between the cores is defined here
 * and nowhere else; docs/amp-protocol.md explains the protocol on top.
 *
 * Rules that make the layout safe without read-modify-write atomics:
 *  - Every 32-byte line has ONE writer, named in the comment of its struct
 *    ("L" = Linux / application core, "S" = servo core). The two semaphore
 *    words are the only exception and are written by token passing: each
 *    side writes its semaphore only in the state that gives it the token
 *    (see AMP_SEM_*).
 *  - While the servo core is offline (before remoteproc starts it, after it
 *    stopped or crashed), Linux owns every word and (re)initialises the
 *    whole region with a new epoch, so contents left from a previous run
 *    or a reset are never mistaken for a live peer.
 *  - All fields are 32-bit words (no sub-word access to OCM, which may be
 *    mapped strongly-ordered); all regions are cache-line aligned so that
 *    cache maintenance of one side's line never touches the other's.
 *  - Little-endian on both sides (ARMv7-A / ARMv7-R / x86-64 host tests).
 *
 * Where the region is (the base is the board's, never this header's: the
 * servo devicetree's amp-region for the firmware, boards/<board>/ for Linux):
 *
 *   board          region                   OCM           who else is in OCM
 *   zynq7000_qemu  0xFFFF0000 + 0x8000      0xFFFC0000    the boot stub and
 *                                           + 256 KiB     park loop, the stop
 *                                                         words, CPU1's boot
 *                                                         register
 *   zynqmp_qemu    0xFFFC0000 + 0x8000      0xFFFC0000    nothing (TF-A is in
 *                                           + 256 KiB     DDR); 0xFFFF0000 is
 *                                                         the R5's high vectors
 *
 * Both cores map it non-cacheable (the A9's MMU, the R5's MPU:
 * AMP_CFG_OCM_CACHED=0).
 */
#ifndef AMP_OCM_LAYOUT_H
#define AMP_OCM_LAYOUT_H

#include <stddef.h>
#include <stdint.h>

#include "amp/amp_config.h"

#define AMP_OCM_MAGIC   0x504d4153u	/* "SAMP" */
#define AMP_OCM_VERSION 1u
#define AMP_FRAME_MAGIC 0x46504d41u	/* "AMPF" */

/* Inter-core semaphore values (the mailbox and the periodic exchange): 1 = idle, 0 = busy. */
#define AMP_SEM_IDLE 1u	/* token with the requester (Linux) */
#define AMP_SEM_BUSY 0u	/* token with the responder (servo) */

/* Linux states (amp_linux_line.state). */
#define AMP_LSTATE_INIT    0x4c494e49u	/* "INIL": region being written */
#define AMP_LSTATE_READY   0x4c445952u	/* "RYDL": region valid, epoch set */
#define AMP_LSTATE_STOPPED 0x4c504f54u	/* "TOPL": Linux closed the link */

/* Servo states (amp_servo_line.state). */
#define AMP_SSTATE_OFFLINE  0u		/* written by Linux at init only */
#define AMP_SSTATE_RUNNING  0x534e5552u	/* "RUNS" */
#define AMP_SSTATE_SAFESTOP 0x53504f54u	/* "TOPS": axes stopped, see fault */
#define AMP_SSTATE_FAULT    0x53544c46u	/* "FLTS": servo-side error */
/* "STPS": stopping on request (remoteproc's stop, seen by the firmware):
 * written before the heartbeat stops, the last word the servo writes */
#define AMP_SSTATE_STOPPING 0x53505453u

/* Control words. Bit 0 of amp_cmd_axis.control_word enables the axis. */
#define AMP_AXIS_ENABLE (1u << 0)

/* Per-axis command, Linux -> servo (16 bytes). Positions in increments. */
struct amp_cmd_axis {
	uint32_t control_word;
	int32_t target_pos;
	int32_t vel_ff;		/* increments / s */
	int32_t torque_offset;	/* milli-percent of rated torque */
};

/* Per-axis feedback, servo -> Linux (20 bytes). */
struct amp_fb_axis {
	uint32_t status_word;
	int32_t actual_pos;
	int32_t actual_vel;	/* increments / s */
	int32_t current;	/* mA */
	int32_t following_error;
};

/*
 * Periodic records are double-buffered: the writer of sequence s writes
 * buffer (s & 1) as seq_begin = s, payload, seq_end = s, then publishes s.
 * The reader reads seq_end, the payload, then seq_begin: equal and equal
 * to the published s means the copy is whole; otherwise it was torn.
 */
struct amp_cmd_record {		/* writer: L */
	_Alignas(AMP_CACHE_LINE) uint32_t seq_begin;
	uint32_t epoch;
	uint32_t cycle;		/* Linux cycle counter when written */
	uint32_t n_axes;
	uint32_t flags;
	uint32_t reserved[3];
	struct amp_cmd_axis axis[AMP_MAX_AXES];
	uint32_t seq_end;
};

struct amp_fb_record {		/* writer: S */
	_Alignas(AMP_CACHE_LINE) uint32_t seq_begin;
	uint32_t epoch;
	uint32_t cmd_seq;	/* last command sequence consumed */
	uint32_t cycle;		/* servo cycle counter */
	uint32_t t_cycle;	/* servo ticks at cycle start */
	uint32_t irq_latency;	/* servo ticks, interrupt to handler */
	uint32_t n_axes;
	uint32_t status;	/* servo state word */
	struct amp_fb_axis axis[AMP_MAX_AXES];
	uint32_t seq_end;
};

/* Variable-length mailbox frame header (32 bytes), followed by payload. */
struct amp_frame_hdr {
	uint32_t magic;		/* AMP_FRAME_MAGIC */
	uint32_t version;	/* AMP_OCM_VERSION */
	uint32_t epoch;
	uint32_t seq;		/* response repeats the request's */
	uint32_t command;	/* application-defined */
	int32_t status;		/* response: 0 or a negative error */
	uint32_t length;	/* payload bytes, <= AMP_MBOX_CAPACITY */
	uint32_t crc32;		/* CRC-32 of header (crc32 = 0) + payload */
};

struct amp_frame {
	_Alignas(AMP_CACHE_LINE) struct amp_frame_hdr hdr;
	uint8_t payload[AMP_MBOX_CAPACITY];
};

struct amp_ocm_header {		/* writer: L, only while the servo is offline */
	uint32_t magic;
	uint32_t version;
	uint32_t total_size;	/* sizeof(struct amp_ocm) */
	uint32_t max_axes;	/* AMP_MAX_AXES of the writer */
	uint32_t mbox_capacity;	/* AMP_MBOX_CAPACITY of the writer */
	uint32_t epoch;		/* new, non-zero value at every init */
	uint32_t wd_limit;	/* watchdog: cycles without heartbeat */
	uint32_t crc32;		/* CRC-32 of the seven words above */
};

struct amp_linux_line {		/* writer: L */
	uint32_t state;		/* AMP_LSTATE_* */
	uint32_t heartbeat;	/* +1 every Linux cycle */
	uint32_t cmd_pub;	/* last published command sequence */
	uint32_t cycle;		/* Linux cycle counter */
	uint32_t mbox_seq;	/* last mailbox request sequence */
	uint32_t reserved[3];
};

struct amp_servo_line {		/* writer: S (Linux zeroes it at init) */
	uint32_t state;		/* AMP_SSTATE_* */
	uint32_t epoch;		/* header epoch the servo attached to */
	uint32_t heartbeat;	/* +1 every servo cycle */
	uint32_t fb_pub;	/* last published feedback sequence */
	uint32_t fault;		/* last servo-side error (AMP_E_* or app) */
	uint32_t attach_count;	/* attaches in this epoch (restarts) */
	uint32_t cmd_stale;	/* cycles without fresh commands */
	uint32_t cmd_missed;	/* command sequences skipped */
};

struct amp_sem_line {		/* writer: token holder (see AMP_SEM_*) */
	uint32_t sem;
	uint32_t reserved[7];
};

struct amp_ocm {
	_Alignas(AMP_CACHE_LINE) struct amp_ocm_header hdr;
	_Alignas(AMP_CACHE_LINE) struct amp_linux_line linux_line;
	_Alignas(AMP_CACHE_LINE) struct amp_servo_line servo_line;
	_Alignas(AMP_CACHE_LINE) struct amp_sem_line cyc_sem;	/* periodic */
	_Alignas(AMP_CACHE_LINE) struct amp_sem_line mbox_sem;	/* mailbox */
	_Alignas(AMP_CACHE_LINE) struct amp_cmd_record cmd[2];
	_Alignas(AMP_CACHE_LINE) struct amp_fb_record fb[2];
	_Alignas(AMP_CACHE_LINE) struct amp_frame req;		/* writer: L */
	_Alignas(AMP_CACHE_LINE) struct amp_frame resp;		/* writer: S */
};

/* ---- layout checks: identical on every compiler and target ---- */
#define AMP__ALIGN_UP(x) (((x) + AMP_CACHE_LINE - 1u) & ~(size_t)(AMP_CACHE_LINE - 1u))
#define AMP_CMD_RECORD_SIZE AMP__ALIGN_UP(32u + 16u * AMP_MAX_AXES + 4u)
#define AMP_FB_RECORD_SIZE  AMP__ALIGN_UP(32u + 20u * AMP_MAX_AXES + 4u)
#define AMP_FRAME_SIZE      AMP__ALIGN_UP(32u + AMP_MBOX_CAPACITY)

#define AMP_OFF_CMD  (5u * AMP_CACHE_LINE)
#define AMP_OFF_FB   (AMP_OFF_CMD + 2u * AMP_CMD_RECORD_SIZE)
#define AMP_OFF_REQ  (AMP_OFF_FB + 2u * AMP_FB_RECORD_SIZE)
#define AMP_OFF_RESP (AMP_OFF_REQ + AMP_FRAME_SIZE)
#define AMP_OCM_SIZE (AMP_OFF_RESP + AMP_FRAME_SIZE)

_Static_assert(AMP_CACHE_LINE == 32 || AMP_CACHE_LINE == 64, "cache line");
_Static_assert(sizeof(struct amp_cmd_axis) == 16, "cmd axis");
_Static_assert(sizeof(struct amp_fb_axis) == 20, "fb axis");
_Static_assert(sizeof(struct amp_frame_hdr) == 32, "frame header");
_Static_assert(sizeof(struct amp_ocm_header) == 32, "header line");
_Static_assert(sizeof(struct amp_linux_line) == 32, "linux line");
_Static_assert(sizeof(struct amp_servo_line) == 32, "servo line");
_Static_assert(sizeof(struct amp_sem_line) == 32, "sem line");
_Static_assert(sizeof(struct amp_cmd_record) == AMP_CMD_RECORD_SIZE, "cmd record");
_Static_assert(sizeof(struct amp_fb_record) == AMP_FB_RECORD_SIZE, "fb record");
_Static_assert(sizeof(struct amp_frame) == AMP_FRAME_SIZE, "frame");
_Static_assert(offsetof(struct amp_ocm, linux_line) == 1u * AMP_CACHE_LINE, "off linux");
_Static_assert(offsetof(struct amp_ocm, servo_line) == 2u * AMP_CACHE_LINE, "off servo");
_Static_assert(offsetof(struct amp_ocm, cyc_sem) == 3u * AMP_CACHE_LINE, "off cyc_sem");
_Static_assert(offsetof(struct amp_ocm, mbox_sem) == 4u * AMP_CACHE_LINE, "off mbox_sem");
_Static_assert(offsetof(struct amp_ocm, cmd) == AMP_OFF_CMD, "off cmd");
_Static_assert(offsetof(struct amp_ocm, fb) == AMP_OFF_FB, "off fb");
_Static_assert(offsetof(struct amp_ocm, req) == AMP_OFF_REQ, "off req");
_Static_assert(offsetof(struct amp_ocm, resp) == AMP_OFF_RESP, "off resp");
_Static_assert(sizeof(struct amp_ocm) == AMP_OCM_SIZE, "total size");

#endif /* AMP_OCM_LAYOUT_H */
