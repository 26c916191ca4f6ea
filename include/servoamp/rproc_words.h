/* SPDX-License-Identifier: (GPL-2.0-only OR MIT) */
/*
 * rproc_words.h - the start/stop contract between the remoteproc driver
 * (linux/remoteproc/zynq_servo_rproc.c) and the servo firmware (rpu_app,
 * the test firmware of tests/robot/fixtures): two 32-bit words in OCM,
 * the driver's control word and, 4 bytes above it, the firmware's status
 * word (addresses: the driver's "reg", the firmware's servo.dts).
 *
 *   start: the driver clears the status word, writes ZSR_CTRL_RUN, points
 *          CPU1's boot register at the entry and waits for ZSR_STATUS_RUNNING;
 *   stop:  the driver writes ZSR_CTRL_STOP and waits for ZSR_STATUS_PARKED,
 *          which the firmware writes just before it branches to the park loop;
 *   fault: the firmware writes ZSR_STATUS_CRASHED and waits for STOP (an
 *          extension: the driver only ever waits for RUN! or PRKD).
 *
 * The one definition of these words (docs/ABI/sysfs-servoamp-remoteproc
 * describes them for users). ZSR_ = Zynq servo remoteproc. Plain integer
 * constants, no types and no includes: the Linux kernel, the freestanding
 * firmware and assembler sources all include this file. STOP, RUN! and
 * PRKD are their ASCII as a big-endian number (a little-endian memory dump
 * shows "POTS"); CRSH, the later extension, is its ASCII in memory.
 */
#ifndef SERVOAMP_RPROC_WORDS_H
#define SERVOAMP_RPROC_WORDS_H

#define ZSR_CTRL_OFFSET		0x0	/* control word, from the driver's reg */
#define ZSR_STATUS_OFFSET	0x4	/* status word, from the driver's reg */

/* control word (written by the driver) */
#define ZSR_CTRL_RUN		0x00000000
#define ZSR_CTRL_STOP		0x53544f50	/* 'STOP' */

/* status word (written by the firmware) */
#define ZSR_STATUS_RUNNING	0x52554e21	/* 'RUN!' */
#define ZSR_STATUS_PARKED	0x50524b44	/* 'PRKD' */
#define ZSR_STATUS_CRASHED	0x48535243	/* "CRSH" in memory: firmware fault */

#endif /* SERVOAMP_RPROC_WORDS_H */
