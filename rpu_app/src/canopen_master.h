/* SPDX-License-Identifier: MIT */
#ifndef RPU_CANOPEN_MASTER_H
#define RPU_CANOPEN_MASTER_H

#include <stdint.h>

#include "can_frame.h"

/*
 * canopen_master.c - a small CANopen master for CiA 402 drives in cyclic
 * synchronous position mode (CSP), one instance per CAN bus.
 *
 * Transport-free: frames come in through co_master_rx() and go out through
 * the send callback given at init, so the logic runs unchanged on the host
 * (tests/rpu_app/test_canopen_master.c) and in the firmware (axis_can.c,
 * over canps.c). Never waits: every call does a bounded amount of work
 * and returns; timeouts are counted in cycles.
 *
 * Per node, from co_master_start():
 *   NMT reset communication -> wait boot-up (0x700+node, byte 0 = 0)
 *   -> SDO configuration, one expedited request outstanding per node
 *      (canopen_config.c):
 *        write 0x6060 = 8 (CSP), read back 0x6061 = 8,
 *        check TPDO1 mapping 0x1A00 = {0x60410010, 0x60640020}
 *        (statusword + position actual) and RPDO1 mapping 0x1600 =
 *        {0x60400010, 0x607A0020} (controlword + target position),
 *        both COB-IDs valid 11-bit identifiers 0x180/0x200 + node (bit 31
 *        clear, bit 29 clear, bits 11-28 clear: anything else is refused
 *        with CO_ERR_PDO_COB_ID and its reason, co_cfg_reason),
 *        both PDOs synchronous (0x1800:02 = 0x1400:02 = 1),
 *        heartbeat producer 0x1017 = hb_producer_ms
 *   -> NMT start -> operational: TPDO1 (0x180+node) read every cycle,
 *      RPDO1 (0x200+node) sent every cycle before the SYNC (0x080).
 *      The NMT start is confirmed by the node's first TPDO1 or a heartbeat
 *      saying Operational within start_timeout_ms; otherwise it is sent
 *      again, start_retries times, then CO_ERR_NMT_START.
 * The CiA 402 enable sequence (shutdown -> switch on -> enable operation,
 * fault reset on the acknowledgement) runs on the statusword each cycle.
 *
 * Supervision of an operational node (every way a drive stops following
 * is an axis fault):
 *   - heartbeat consumer: silent for more than hb_consumer_ms (once its
 *     first heartbeat is seen, or from NMT start): CO_ERR_HEARTBEAT;
 *   - NMT state: a heartbeat saying pre-operational (0x7F) or stopped
 *     (0x04), or an NMT command of another master on the bus sending the
 *     node there: CO_ERR_NMT_PREOP / CO_ERR_NMT_STOPPED in the cycle that
 *     reads it; the node gets NMT start again on the acknowledgement.
 *     After a start, a heartbeat counts once the node's heartbeat has
 *     said Operational or its TPDO1 fell silent: before, it may be the one
 *     sent before the node handled the start, behind its first TPDO1;
 *   - TPDO silence: pdo_timeout_cycles consecutive cycles whose SYNC went
 *     out without the node's TPDO1: CO_ERR_PDO_TIMEOUT (a later heartbeat
 *     timeout or NMT state names the cause: the code is refined);
 *   - EMCY (0x80+node) with a non-zero code: the drive's error code;
 *   - a statusword in Fault without an EMCY: CO_ERR_DRIVE_FAULT.
 * Faults are latched until the operator acknowledges them
 * (co_master_acknowledge: the servo's resume), not by the axis' enable
 * request going off and on again (Linux drops it for a cycle when a
 * program ends in fault: that is no acknowledgement). The acknowledgement
 * clears the latched code and the drive's last EMCY code, sends NMT start
 * to a node that left Operational, retries a failed start-up, and gives a
 * drive in Fault a fault reset: bit 7 of the controlword, after a word with
 * it clear, held until the drive's statusword leaves Fault or
 * fault_reset_ms has passed (then CO_ERR_FAULT_RESET, "fault reset
 * refused by drive"). A reset word the TX path refused is sent again.
 *
 * Everything received is bounds-checked: the DLC (0..8, and the length
 * each protocol needs), the node id (1..127, and one of ours), the SDO
 * command specifier, index, subindex and size.
 */

#define CO_MAX_NODES 8u		/* nodes per bus (master) */

/* Returns 0 when the frame was queued, non-zero when the TX path is full. */
typedef int (*co_send_fn)(void *ctx, const struct can_frame *f);

/* Node (axis) progress through the start-up. */
enum co_node_phase {
	CO_PH_IDLE = 0,		/* not started */
	CO_PH_RESET,		/* NMT reset communication to send */
	CO_PH_BOOT_WAIT,	/* waiting for the boot-up message */
	CO_PH_CONFIG,		/* SDO configuration */
	CO_PH_START,		/* NMT start to send */
	CO_PH_OPERATIONAL,	/* PDOs every cycle */
	CO_PH_FAILED,		/* configuration refused: never operational */
};

/* CiA 402 drive states, decoded from the statusword (0x6041). */
enum co_402_state {
	CO402_UNKNOWN = 0,	/* no statusword yet */
	CO402_NOT_READY,	/* not ready to switch on */
	CO402_SWITCH_ON_DISABLED,
	CO402_READY_TO_SWITCH_ON,
	CO402_SWITCHED_ON,
	CO402_OPERATION_ENABLED,
	CO402_QUICK_STOP_ACTIVE,
	CO402_FAULT_REACTION_ACTIVE,
	CO402_FAULT,
};

/* Controlword commands (CiA 402). */
#define CO_CW_DISABLE_VOLTAGE 0x0000u
#define CO_CW_SHUTDOWN 0x0006u
#define CO_CW_SWITCH_ON 0x0007u
#define CO_CW_ENABLE_OPERATION 0x000Fu
#define CO_CW_FAULT_RESET 0x0080u

/* Axis fault codes raised by the master itself (CiA 301 EMCY classes). */
#define CO_ERR_HEARTBEAT 0x8130u	/* life guard / heartbeat error */
#define CO_ERR_BUS_OFF 0x8140u		/* recovered from bus off */
#define CO_ERR_BOOT_TIMEOUT 0xFF01u	/* no boot-up after every NMT reset retry */
#define CO_ERR_CONFIG 0xFF02u		/* SDO configuration refused / mapping wrong */
#define CO_ERR_RESTARTED 0xFF03u	/* boot-up while operational: the node restarted */
#define CO_ERR_NMT_PREOP 0xFF04u	/* left Operational: heartbeat/NMT says pre-operational */
#define CO_ERR_NMT_STOPPED 0xFF05u	/* left Operational: heartbeat/NMT says stopped */
#define CO_ERR_PDO_TIMEOUT 0xFF06u	/* pdo_timeout_cycles cycles without the node's TPDO1 */
#define CO_ERR_NMT_START 0xFF07u	/* NMT start never confirmed, after every retry */
#define CO_ERR_PDO_COB_ID 0xFF08u	/* a PDO COB-ID the master does not support */
#define CO_ERR_FAULT_RESET 0xFF09u	/* fault reset refused by drive: still in Fault */
#define CO_ERR_DRIVE_FAULT 0x1000u	/* drive in Fault without an EMCY: generic error */

/* Why a configuration was refused (co_node.cfg_reason). */
enum co_cfg_reason {
	CO_CFG_OK = 0,
	CO_CFG_SDO_ABORT,	/* the node aborted the transfer (co_node.sdo_abort) */
	CO_CFG_SDO_TIMEOUT,	/* no answer after every retry */
	CO_CFG_SDO_PROTOCOL,	/* an answer that is not the expected expedited one */
	CO_CFG_VALUE,		/* a value other than the one needed (mode, mapping) */
	CO_CFG_COB_INVALID,	/* PDO COB-ID bit 31 set: PDO not valid */
	CO_CFG_COB_29BIT,	/* PDO COB-ID bit 29 set: 29-bit identifier */
	CO_CFG_COB_BITS,	/* PDO COB-ID bits 11-28 set */
	CO_CFG_COB_ID,		/* PDO COB-ID not 0x180/0x200 + node */
};

struct co_config {
	uint32_t period_us;		/* cycle period (timeouts are counted in cycles) */
	uint16_t hb_producer_ms;	/* written to each node's 0x1017 */
	uint16_t hb_consumer_ms;	/* node silent longer than this: axis fault */
	uint16_t sdo_timeout_ms;	/* one SDO request */
	uint16_t boot_timeout_ms;	/* boot-up after an NMT reset */
	uint8_t boot_retries;		/* NMT resets before CO_ERR_BOOT_TIMEOUT */
	uint8_t sdo_retries;		/* per request, on timeout */
	uint16_t stamp_ms;		/* the master's time stamp every this often, 0: never */
	/* 0 in any of these: the default in brackets */
	uint16_t start_timeout_ms;	/* NMT start confirmed within this [50] */
	uint8_t start_retries;		/* NMT starts sent again before CO_ERR_NMT_START [3] */
	uint8_t pdo_timeout_cycles;	/* cycles without TPDO1 before CO_ERR_PDO_TIMEOUT [2] */
	uint16_t fault_reset_ms;	/* reset bit held at most this long [100] */
};
#define CO_DEFAULT_START_TIMEOUT_MS 50u
#define CO_DEFAULT_START_RETRIES 3u
#define CO_DEFAULT_PDO_TIMEOUT_CYCLES 2u
#define CO_DEFAULT_FAULT_RESET_MS 100u

struct co_node {
	uint8_t node_id;	/* 1..127 */
	uint8_t phase;		/* enum co_node_phase */
	uint8_t state402;	/* enum co_402_state */
	uint8_t nmt_state;	/* NMT state last seen (0 boot-up, 4, 5, 127; a heartbeat, another
				 * master's NMT, 5 with a TPDO1), 0xFF none */
	uint8_t step;		/* configuration step */
	uint8_t sdo_busy;	/* a request is outstanding */
	uint8_t tries;		/* NMT resets / SDO tries of the current step */
	uint8_t enable_req;	/* the axis' enable request (co_master_set) */
	uint8_t ack_req;	/* the operator's acknowledgement, for the next cycle */
	uint8_t reset_active;	/* a fault reset runs (bit 7 held) */
	uint8_t reset_sent;	/* ... and bit 7 went out after a word with it clear */
	uint8_t ack_wait;	/* acknowledged before the 402 state was known */
	uint8_t confirmed;	/* NMT start confirmed (TPDO1 or heartbeat 0x05) */
	uint8_t hb_confirmed;	/* a heartbeat 0x05 since the NMT start: the
				 * node's later heartbeats follow the start */
	uint8_t nmt_lost;	/* left Operational after the start was confirmed */
	uint8_t pdo_silent;	/* consecutive cycles without TPDO1 */
	uint8_t start_tries;	/* NMT starts sent again */
	uint8_t cfg_reason;	/* enum co_cfg_reason of a refused configuration */
	uint8_t hb_armed;	/* heartbeat consumer running */
	uint8_t tpdo_seen;	/* TPDO1 received since the last SYNC */
	uint8_t fault;		/* latched axis fault */
	uint8_t pos_valid;	/* pos_actual holds a value from the drive */
	uint16_t statusword;	/* 0x6041 from the last TPDO1 */
	uint16_t controlword;	/* 0x6040 sent in the last RPDO1 */
	uint16_t error_code;	/* the latched fault's code (EMCY or CO_ERR_*) */
	uint16_t emcy_last;	/* last EMCY code received (0: none) */
	int32_t pos_actual;	/* 0x6064 from the last TPDO1 */
	int32_t target;		/* the axis' target (co_master_set) */
	int32_t target_sent;	/* 0x607A sent in the last RPDO1 */
	uint16_t cfg_index;	/* the object whose check refused it */
	uint8_t cfg_sub;
	uint32_t cfg_value;	/* the value read from it */
	uint32_t deadline;	/* cycle at which the boot/SDO/start wait times out */
	uint32_t reset_deadline;	/* cycle at which a fault reset is given up */
	uint32_t hb_last;	/* cycle of the last heartbeat (or NMT start) */
	uint32_t sdo_abort;	/* last SDO abort code received */
	uint32_t tpdo_count;	/* TPDO1s received */
};

/* The master's counters: one struct, read as a whole (co_master_stats). */
struct co_stats {
	uint32_t cycles;		/* co_master_cycle calls */
	uint32_t sync_sent;
	uint32_t sync_missed;		/* SYNC not sent: TX path full */
	uint32_t rpdo_sent;
	uint32_t rpdo_missed;		/* RPDO not sent: TX path full */
	uint32_t tpdo_rx;
	uint32_t pdo_missing;		/* operational nodes whose TPDO1 did not come in a cycle */
	uint32_t pdo_missing_last;	/* of the last cycle */
	uint32_t pdo_missing_max;	/* in one cycle */
	uint32_t emcy;			/* EMCY frames with a non-zero code */
	uint32_t hb_rx;
	uint32_t hb_timeouts;
	uint32_t bootups;
	uint32_t nmt_sent;
	uint32_t sdo_req, sdo_ok, sdo_abort, sdo_timeout, sdo_bad;
	uint32_t rx_frames;		/* frames given to co_master_rx */
	uint32_t rx_ignored;		/* not for us (other COB-IDs, other nodes) */
	uint32_t rx_bad;		/* malformed: DLC too short / out of range, RTR */
	uint32_t tx_busy;		/* any frame refused by the TX path */
	uint32_t bus_off;		/* bus-off events reported (co_master_bus_off) */
	uint32_t faults;		/* axis faults raised */
	uint32_t nodes_operational;	/* nodes now in CO_PH_OPERATIONAL */
	uint32_t stamps_sent;		/* time stamps (co_master_time_stamp) */
	uint32_t pdo_timeouts;		/* CO_ERR_PDO_TIMEOUT raised or refined */
	uint32_t nmt_left;		/* nodes seen leaving Operational */
	uint32_t nmt_foreign;		/* NMT commands of another master for our nodes */
	uint32_t start_retries;		/* NMT starts sent again, unconfirmed */
	uint32_t fault_resets;		/* fault resets begun */
	uint32_t fault_reset_refused;	/* ... and given up (drive still in Fault) */
};

struct co_master {
	co_send_fn send;
	void *ctx;
	struct co_config cfg;
	uint32_t cycle;
	uint32_t hb_consumer_cycles, sdo_timeout_cycles, boot_timeout_cycles, stamp_cycles;
	uint32_t start_timeout_cycles, start_retries, pdo_timeout_cycles, fault_reset_cycles;
	uint32_t n_nodes;
	uint32_t supervised;	/* co_master_supervise done for this cycle */
	struct co_node node[CO_MAX_NODES];
	uint8_t index_of[128];	/* node id -> node[] index, 0xFF: not ours */
	struct co_stats st;
};

/*
 * The master's clock on the bus: CiA 301's high-resolution time stamp
 * (object 0x1013, UNSIGNED32, microseconds), sent as a PDO of the master's
 * own node id, CO_MASTER_NODE_ID, every cfg.stamp_ms, as the first frame of
 * its cycle (the bus is idle then: the drives answered the last SYNC long
 * before). A host that sees the frame's time on the bus (servoamp bridge)
 * relates the servo core's clock to it (docs/fieldbus.md "Time stamp").
 * With stamps on, no drive may take that node id.
 */
#define CO_MASTER_NODE_ID 127u
#define CO_COB_TIME_STAMP (0x180u + CO_MASTER_NODE_ID)

/* 0, or -1 for a node id out of 1..127 (1..126 with time stamps), a
 * duplicate, or too many nodes. */
int co_master_init(struct co_master *m, co_send_fn send, void *ctx, const struct co_config *cfg,
		   const uint8_t *node_ids, uint32_t n_nodes);
/* Begin the start-up of every node (NMT reset on the next cycle). */
void co_master_start(struct co_master *m);
/* One received frame (any COB-ID; what is not ours is counted and dropped). */
void co_master_rx(struct co_master *m, const struct can_frame *f);
/* The supervision of this cycle, once the frames received are in
 * (co_master_rx): the cycle counter, TPDO silence, the heartbeat consumer,
 * the NMT start's confirmation. Call it before reading the nodes for the
 * axes' feedback, so that a fault shows in this cycle; co_master_cycle
 * does it if the caller did not. */
void co_master_supervise(struct co_master *m);
/* One cycle: the supervision (if not done), start-up steps, RPDOs then SYNC. */
void co_master_cycle(struct co_master *m);
/* 1 when the next co_master_cycle is a time-stamp cycle (then call
 * co_master_time_stamp first, with the time read just before). */
int co_master_stamp_due(const struct co_master *m);
void co_master_time_stamp(struct co_master *m, uint32_t now_us);
/* The axis' command for the next cycle's RPDO. */
void co_master_set(struct co_master *m, uint32_t idx, int enable, int32_t target);
/* The operator's acknowledgement (the servo's resume), taken in the next
 * cycle: the latched fault and the drive's last EMCY code are cleared, a
 * drive in Fault is reset, a node out of Operational is started again, a
 * failed start-up is retried. Nothing else clears a latched fault. */
void co_master_acknowledge(struct co_master *m, uint32_t idx);
/* The bus went off (and was restarted by the driver): every operational
 * node's axis faults with CO_ERR_BUS_OFF; counted. */
void co_master_bus_off(struct co_master *m);
const struct co_node *co_master_node(const struct co_master *m, uint32_t idx);
void co_master_stats(const struct co_master *m, struct co_stats *out);

enum co_402_state co_402_decode(uint16_t statusword);
/* "pre-operational", "stopped", ... of a heartbeat's NMT state. */
const char *co_nmt_name(uint8_t nmt_state);
/* What a refusal's reason means ("29-bit identifier (bit 29)", ...). */
const char *co_cfg_reason_name(enum co_cfg_reason r);
const char *co_402_name(enum co_402_state s);
const char *co_phase_name(enum co_node_phase p);

#endif
