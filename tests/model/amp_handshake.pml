/*
 * amp_handshake.pml - Promela model of amp_lib's handshake between Linux
 * (CPU0: amp_lib/src/amp_linux.c, driven by linux/servod) and the servo
 * core (CPU1: amp_lib/src/amp_servo.c, driven by rpu_app/src/link.c): the
 * region's epoch and the attach, the periodic exchange (double-buffered
 * seqlock records, cmd_pub / fb_pub, the cycle semaphore) and the mailbox
 * (request and response frames, the mailbox semaphore).
 * docs/amp-protocol.md section 9 maps every step to the C code and says what
 * is abstracted away; tests/model/test_spin.py runs the checks.
 *
 * Each step of a process is one load or one store of one shared word (plus
 * private bookkeeping), in the order of the C code, under sequential
 * consistency (the barriers of amp_lib's port give that order); a few loads
 * or stores are one step where no interleaving between them gives another
 * outcome (said where it is done). Spin explores every interleaving of the
 * two cores and of the faults.
 *
 * Faults, at any interleaving point until the drain begins (NL Linux
 * cycles, the servo at most LEAD cycles ahead, Linux any number ahead):
 *   - Linux (servod) crashes (MAXLC) at any step, inside amp_linux_init too,
 *     and initialises the region again. By amp_linux_init's contract
 *     (amp.h; linux/servod/supervisor.c makes a new region only once
 *     remoteproc says "offline") the servo core is stopped first and started
 *     again once the region is ready. -DLIVE_INIT breaks that contract: the
 *     region is initialised again while the servo still runs;
 *   - the servo crashes (MAXSC) at any step and restarts (remoteproc
 *     recovery): its private state is lost, it attaches again in the same
 *     epoch;
 *   - a stray write (MAXCOR) to any control word: the semaphores, both
 *     lines' state and epoch words, cmd_pub, fb_pub, the attach count, the
 *     heartbeat, the header; a value of each class the readers tell apart.
 *     A record's sequence or epoch word, or a mailbox frame, is spoilt (a
 *     frame then fails its CRC: the CRC is modelled as "a corrupted or
 *     half-written frame is detected").
 * Then the drain: no more faults, both cores take every cycle interrupt
 * (the servo's cycle n and Linux's cycle n overlap in any way, neither
 * starts cycle n+1 before the other has finished cycle n), at most K Linux
 * cycles.
 *
 * Properties (chosen with -DCHECK_*; FRESH, ACK and RESUME by default):
 *   FRESH   a record the reader takes (feedback by Linux, commands by the
 *           servo) is whole (no write to it while it was copied), was
 *           written by a peer of the reader's own session, and is newer
 *           than the last record this reader took (Linux: in its session;
 *           the servo: since its attach); a mailbox answer Linux takes
 *           (other than an AMP_E_PROTO refusal) answers its own request:
 *           nothing stale is taken as fresh;
 *   ACK     the command sequence the servo acknowledges in the feedback
 *           Linux takes (fb.cmd_seq, "last command sequence consumed") was
 *           taken by a servo of this session: no command acknowledged but
 *           lost;
 *   RESUME  no deadlock: within K Linux cycles of the drain a command
 *           published in the drain is taken and acknowledged in feedback
 *           Linux takes, and a mailbox request is answered (the caller's
 *           timeout cancels a request after TMO polls), or
 *           amp_linux_cycle reports an error servod recovers from
 *           (AMP_E_STALLED, AMP_E_FEEDBACK, AMP_E_PEER_ERROR);
 *   ACKSEM  (not by default, and false: the semaphore is a hint, the
 *           sequence decides) the cycle semaphore found idle means the
 *           servo took the command it was set busy for;
 *   and spin's own: no invalid end state.
 * -DMUTANT_* puts back the code as it was before a fix of issue 20 item 7b,
 * or removes one safeguard: spin must then find a violation
 * (tests/model/test_spin.py checks it does):
 *   NO_BEGIN       Linux does not compare a record's seq_begin
 *   NO_EPOCH       nor its epoch word
 *   NO_CMD_RESYNC  the servo does not resynchronise its commands on attach
 *   NO_SEM_REPAIR  a garbled mailbox semaphore is taken for busy
 *   NO_DUP         (before) no "the record Linux holds" check
 *   ACK_ATTACH     (before) feedback acknowledges the cmd_pub of the attach
 *   NO_SKIP        (before) the attach continues after fb_pub only
 *   NO_REASSERT    (before) Linux writes its header and state at init only
 *   PEER_ABSENT    (before) OFFLINE, or another epoch before Linux saw the
 *                  attach, is "absent"
 * -DNO_MBOX / -DNO_PERIODIC leave one of the two exchanges out: they share
 * no word, so each is checked on its own. The checks of the test suite
 * (docs section 9):
 *
 *   spin -a -DNO_MBOX -DMAXLC=0 amp_handshake.pml     servo crash + stray write
 *   spin -a -DNO_MBOX -DMAXSC=0 -DMAXCOR=0 ...        Linux crash
 *   spin -a -DNO_PERIODIC -DMAXLC=0 ...               the same for the mailbox
 *   spin -a -DNO_PERIODIC -DMAXSC=0 -DMAXCOR=0 ...
 *   gcc -O2 -DSAFETY -DCOLLAPSE -o pan pan.c && ./pan -m20000 -w24
 */

/* ---------------- bounds ---------------- */
#ifndef NL
#define NL 1		/* Linux cycles before the drain (all sessions) */
#endif
#ifndef K
#ifdef NO_PERIODIC
#define K 7		/* the drain: Linux cycles until the link has resumed */
#else
#define K 4
#endif
#endif
#ifndef NR
#define NR 1		/* mailbox requests posted before the drain */
#endif
#ifndef TMO
#define TMO 3		/* unanswered polls in the drain before the caller gives up */
#endif
#ifndef MAXLC
#define MAXLC 1		/* Linux crashes */
#endif
#ifndef MAXSC
#define MAXSC 1		/* servo crashes */
#endif
#ifndef MAXCOR
#define MAXCOR 1	/* stray writes */
#endif
#ifndef LEAD
#define LEAD 1		/* before the drain: the servo at most LEAD interrupts ahead */
#endif
#define WD   2		/* watchdog limit (header wd_limit) */
#define HBM  3		/* the servo's heartbeat modulo HBM (at most 2 beats
			 * between two of Linux's reads; compared for equality) */
#define FAR  100	/* a sequence value no record of the run has */

#if !defined(CHECK_FRESH) && !defined(CHECK_ACK) && !defined(CHECK_RESUME) && !defined(CHECK_ACKSEM)
#define CHECK_FRESH
#define CHECK_ACK
#define CHECK_RESUME
#endif
#ifndef LIVE_INIT
#define OFFLINE_INIT
#endif

/* ---------------- the region's words (amp_ocm_layout.h) ---------------- */
#define BUSY 0		/* AMP_SEM_BUSY */
#define IDLE 1		/* AMP_SEM_IDLE */
#define GARB 3		/* a word that is no value of its kind */

#define L_INIT 1	/* AMP_LSTATE_INIT */
#define L_READY 2	/* AMP_LSTATE_READY */

#define S_OFFLINE 0	/* AMP_SSTATE_OFFLINE (the zeroed line) */
#define S_RUNNING 1
#define S_SAFESTOP 2
#define S_FAULT 3

#define R_OK 0
#define R_ABSENT 1	/* AMP_E_PEER_ABSENT */
#define R_PERR 2	/* AMP_E_PEER_ERROR */
#define R_STALLED 3	/* AMP_E_STALLED */
#define R_FEEDBACK 4	/* AMP_E_FEEDBACK */

#define C_STALE 0	/* amp__rx_classify / amp__rx_record */
#define C_FRESH 1
#define C_MISSED 2
#define C_INVALID 3
#define C_TORN 4

bit  hdr_ok;		/* hdr.magic, the fields and hdr.crc32 check */
byte hdr_epoch;		/* hdr.epoch */
byte l_state;		/* linux_line.state */
byte cmd_pub;		/* linux_line.cmd_pub */
byte s_state;		/* servo_line.state */
byte s_epoch;		/* servo_line.epoch */
byte s_hb;		/* servo_line.heartbeat (mod HBM) */
byte fb_pub;		/* servo_line.fb_pub */
byte s_attach;		/* servo_line.attach_count */
byte cyc_sem;		/* cyc_sem.sem */
byte mbox_sem;		/* mbox_sem.sem */
byte cmd_b[2];		/* cmd[i].seq_begin */
byte cmd_ep[2];		/* cmd[i].epoch (the payload) */
byte cmd_e[2];		/* cmd[i].seq_end */
byte fb_b[2];		/* fb[i].seq_begin */
byte fb_ep[2];		/* fb[i].epoch   } the payload */
byte fb_cs[2];		/* fb[i].cmd_seq } */
byte fb_e[2];		/* fb[i].seq_end */
bit  req_ok;		/* req frame whole (magic, version, length, CRC) */
byte req_ep;
byte req_seq;
bit  rsp_ok;		/* resp frame whole */
bit  rsp_proto;		/* resp.status is AMP_E_PROTO (the request was refused) */
byte rsp_ep;
byte rsp_seq;

/* ---------------- faults and scheduling ---------------- */
bit  faults_off;	/* the drain has begun */
bit  l_kill, s_kill;	/* a crash is due: taken at the process's next step */
#ifdef OFFLINE_INIT
bit  s_off = 1;		/* remoteproc holds the servo core stopped */
bit  s_run;		/* the servo core runs (remoteproc: not "offline") */
#endif
byte nlc, nsc, ncor;
short lead;		/* servo interrupts minus Linux cycles */

/* ---------------- ghosts (the observer's, not in OCM) ---------------- */
byte g_sess;		/* Linux sessions begun (amp_linux_init calls) */
byte l_sess;		/* the running Linux's session */
byte g_ep;		/* its epoch */
byte g_hdr_sess;	/* the session whose header is in OCM */
/* per record buffer: G_NONE zeroed, G_WRITING begun and not ended, G_NEW
 * whole and newer than every record the reader took, G_OLD taken, or
 * older than one taken */
#define G_NONE 0
#define G_WRITING 1
#define G_NEW 2
#define G_OLD 3
byte gcmd_st[2];
byte gcmd_sess[2];	/* the writer's session */
byte gcmd_rd;		/* the reader is copying cmd[gcmd_rd - 1] (0: none) */
bit  gcmd_dirty;	/* and it has been written since the copy began */
bit  gcmd_last;		/* the buffer written last */
byte gfb_st[2];
byte gfb_sess[2];
byte gfb_rd;
bit  gfb_dirty;
bit  gfb_last;
bit  gfb_held[2];	/* fb[i] holds what Linux holds in l->fb (the record it
			 * took last): not written since (a record written
			 * again differs in its cycle, tick and axis words) */
int  g_taken;		/* bit c: command c of this session taken by its servo */
#ifdef CHECK_ACKSEM
byte g_tok;		/* the command the cycle semaphore was last set busy for */
#endif
byte g_rq;		/* mailbox requests posted */
byte greq_id, greq_sess;	/* the request in req */
byte grsp_id, grsp_sess;	/* what resp answers */

/* ---------------- helpers ---------------- */
/* a write to record i: the reader copying it has a torn copy */
inline cmd_wr(i)
{
	if
	:: gcmd_rd == i + 1 -> gcmd_dirty = 1
	:: else
	fi
}

inline fb_wr(i)
{
	if
	:: gfb_rd == i + 1 -> gfb_dirty = 1
	:: else
	fi
}

/* amp__rx_classify, then amp__rx_record's resynchronisation */
inline classify(p, last, rs, cls)
{
	if
	:: p == last -> cls = C_STALE
	:: p < last -> cls = C_INVALID	/* went backwards: reordered */
	:: p == last + 1 -> cls = C_FRESH
	:: else -> cls = C_MISSED
	fi;
	if
	:: rs -> cls = C_FRESH
	:: else
	fi
}

/* amp_servo.c seq_newest: n := w if w is ahead of n */
inline newest(n, w)
{
	if
	:: w > n -> n = w
	:: else
	fi
}

/* the reader took buffer b: it is old now, so is the other one if older */
inline take_fb(b)
{
	gfb_st[b] = G_OLD;
	if
	:: gfb_last == b && gfb_st[1 - b] == G_NEW -> gfb_st[1 - b] = G_OLD
	:: else
	fi
}

inline take_cmd(b)
{
	gcmd_st[b] = G_OLD;
	if
	:: gcmd_last == b && gcmd_st[1 - b] == G_NEW -> gcmd_st[1 - b] = G_OLD
	:: else
	fi
}

/* amp_linux_peer: the servo line's epoch (acquire), its state, and (for
 * another epoch) its attach count; one step: the servo writes its attach
 * count, then its state, then its epoch, so no interleaving between the
 * loads gives another answer. A servo attached in this epoch (seen, or an
 * attach count, which Linux zeroed) never writes another epoch, nor
 * OFFLINE: such a word is a stray write, a peer error, which servod
 * recovers, not an absence it would wait on forever */
inline l_peer(r)
{
	x = s_epoch;
	y = s_state;
#ifdef MUTANT_PEER_ABSENT
	if
	:: x != ep -> r = (seen -> R_PERR : R_ABSENT)
	:: else ->
		if
		:: y == S_RUNNING || y == S_SAFESTOP -> r = R_OK
		:: y == S_OFFLINE -> r = R_ABSENT
		:: else -> r = R_PERR
		fi
	fi;
#else
	if
	:: x != ep -> r = ((seen || s_attach != 0) -> R_PERR : R_ABSENT)
	:: else -> r = ((y == S_RUNNING || y == S_SAFESTOP) -> R_OK : R_PERR)
	fi;
#endif
	x = 0; y = 0
}

/* ---------------- Linux ---------------- */

/* amp_linux_cycle: sets rc, took, ack */
inline l_cycle()
{
	if
	:: faults_off -> lead >= 0	/* the servo has finished the last cycle */
	:: else
	fi;
	d_step {
		if
		:: !faults_off && lead > -LEAD -> lead--
		:: else
		fi;
		l_peer(peer);
		/* 1. l->cycle++; check_attach: the first attach in this epoch */
		cyc++; took = 0;
		if
		:: !seen && (peer == R_OK || peer == R_PERR) -> seen = 1; first = 1
		:: else
		fi
	};
	if
	:: seen ->
		d_step {	/* check_attach: attach_count changed (read once) */
			x = s_attach;
			if
			:: x != sattach || first ->
				sattach = x; wprimed = 0; fresync = 1; fbad = 0
			:: else
			fi;
			x = 0; first = 0
		}
	:: else
	fi;
#ifndef NO_PERIODIC
#ifdef CHECK_ACKSEM
	d_step {	/* 2. a busy semaphore: the servo is late */
		assert(cyc_sem != IDLE || g_tok == 0 || (g_tok < 31 && ((g_taken >> g_tok) & 1)))
	};
#endif
	/* 2. fb_pub (acquire), classified: the record it names is read in
	 * step 5, after the publication */
	d_step { pub = fb_pub; classify(pub, fseq, fresync, cls) };
	/* 3. amp__rec_write of cmd[seq & 1]: seq_begin, the payload, seq_end */
	d_step {
		seq = cseq + 1; b = seq & 1;
		cmd_b[b] = seq;
		gcmd_st[b] = G_WRITING; cmd_wr(b);
		gcmd_sess[b] = l_sess; gcmd_last = b
	};
	d_step { cmd_ep[b] = ep; cmd_wr(b) };
	d_step { cmd_e[b] = seq; cmd_wr(b); gcmd_st[b] = G_NEW };
	/* 4. busy if the token is ours (idle, or a word neither idle nor
	 * busy: sem_corrupt), THEN publish */
	d_step { x = cyc_sem };
	if
	:: x != BUSY ->
		d_step {
			cyc_sem = BUSY; x = 0;
#ifdef CHECK_ACKSEM
			g_tok = seq
#endif
		}
	:: else -> x = 0
	fi;
#endif
#ifndef MUTANT_NO_REASSERT
	/* 4. Linux's own words written again, unchanged: the header (from the
	 * copy written at init), then its state. One step: the servo reads the
	 * two together, and a single stray write makes only one of them
	 * differ */
	d_step { hdr_ok = 1; hdr_epoch = ep; g_hdr_sess = l_sess; l_state = L_READY };
#endif
#ifndef NO_PERIODIC
	d_step { cmd_pub = seq; cseq = seq; seq = 0; b = 0 };
	/* 5. read_feedback, after the publication (the feedback's lines move
	 * while the servo takes the commands): amp__rx_record of the record
	 * fb_pub named in step 2 */
	if
	:: cls == C_FRESH || cls == C_MISSED ->
		/* amp__rec_read: seq_end, the payload, seq_begin */
		d_step { b = pub & 1; e = fb_e[b]; gfb_rd = b + 1; gfb_dirty = 0; same = gfb_held[b] };
		d_step {
			x = fb_ep[b]; y = fb_cs[b];
			/* the copy is whole iff nothing wrote the record since
			 * seq_end was read and the record was complete then */
			gwhole = (!gfb_dirty && gfb_st[b] != G_WRITING);
			gnew = (gfb_st[b] == G_NEW); gsess = gfb_sess[b];
			/* the copy is what l->fb holds: the record was when seq_end
			 * was read and the writer has not touched it since
			 * (seq_begin, read last, must equal seq_end anyway) */
			same = (same && !gfb_dirty);
			gfb_rd = 0; gfb_dirty = 0
		};
		d_step {
			bb = fb_b[b];
#ifdef MUTANT_NO_DUP
			same = 0;
#endif
#ifdef MUTANT_NO_BEGIN
			bb = e;		/* seq_begin not compared */
#endif
#ifdef MUTANT_NO_EPOCH
			x = ep;		/* the record's epoch not compared */
#endif
			if
			:: bb == e && e == pub && x == ep && !same ->
				took = 1; fseq = pub; ack = y; fresync = 0; fbad = 0;
				gfb_held[b] = 1; gfb_held[1 - b] = 0;
#ifdef CHECK_FRESH
				assert(gwhole);			/* whole */
				assert(gnew);			/* newer than the last taken */
				assert(gsess == l_sess);	/* of this session */
#endif
#ifdef CHECK_ACK
				assert(ack == 0 || (ack < 31 && ((g_taken >> ack) & 1)));
#endif
				take_fb(b)
			:: else ->
				cls = ((bb == e && e == pub) -> (same -> C_STALE : C_INVALID) : C_TORN);
				if
				:: pub == fseq -> cls = C_STALE	/* nothing new yet */
				:: else
				fi
			fi;
			/* read_feedback: from a refused read on, every cycle
			 * without a record taken counts (capped: only ">= WD" is
			 * asked) */
			if
			:: !took && (cls == C_INVALID || cls == C_TORN || fbad > 0) && fbad < WD -> fbad++
			:: else
			fi;
			bb = 0; e = 0; x = 0; y = 0; b = 0; gwhole = 0; gnew = 0; gsess = 0; same = 0;
			pub = 0; cls = 0
		}
	:: else ->
		d_step {
			if
			:: (cls == C_INVALID || fbad > 0) && fbad < WD -> fbad++
			:: else
			fi;
			pub = 0; cls = 0
		}
	fi;
#else
	d_step { cseq++ };	/* the sequence only, for the drain's target */
#endif
	/* the watchdog, from the servo's first attach on; then AMP_E_FEEDBACK */
	d_step {
		if
		:: !seen -> wprimed = 0; rc = peer
		:: else ->
			x = s_hb;
			if		/* amp_wd_feed */
			:: !wprimed || x != wlast -> wlast = x; wstill = 0; wprimed = 1
			:: else ->
				if
				:: wstill < WD -> wstill++
				:: else
				fi
			fi;
			if
			:: wstill >= WD -> rc = R_STALLED
			:: else -> rc = (fbad >= WD -> R_FEEDBACK : peer)
			fi
		fi;
		x = 0; peer = 0;
		if
		:: faults_off -> lead--	/* done: the servo may take the next one */
		:: else
		fi
	}
}

/* amp_linux_mbox_post */
inline l_post()
{
	d_step { l_peer(rc) };
	if
	:: rc == R_OK ->
		d_step { x = mbox_sem; rc = 0 };
		if
		:: x == BUSY -> x = 0	/* AMP_E_BUSY: posted again later */
#ifdef MUTANT_NO_SEM_REPAIR
		:: x != BUSY && x != IDLE -> x = 0	/* garbage taken for busy */
#endif
		:: else ->		/* (sem_corrupt if garbage) amp__frame_put */
			d_step { x = 0; mseq++; g_rq++; rq = g_rq; req_ok = 0 };
			d_step { req_ok = 1; req_ep = ep; req_seq = mseq;
				 greq_id = rq; greq_sess = l_sess };
			d_step { mbox_sem = BUSY; pending = 1; npoll = 0 }
		fi
	:: else -> rc = 0
	fi
}

/* amp_linux_mbox_poll */
inline l_poll()
{
	d_step { x = mbox_sem };
	if
	:: x != IDLE -> x = 0	/* AMP_E_BUSY, or amp_linux_peer's error */
	:: else ->
		d_step {	/* amp__frame_recv: one copy, checked; the seq */
			x = 0; pending = 0;
			if
			:: rsp_ok && rsp_ep == ep && rsp_seq == mseq ->
#ifdef CHECK_FRESH
				assert(rsp_proto || (grsp_id == rq && grsp_sess == l_sess));
#endif
				if :: faults_off -> ok_mb = 1 :: else fi
			:: else
			fi
		}
	fi
}

proctype Linux()
{
	byte ep;		/* l->epoch */
	byte cseq, fseq;	/* l->cmd_seq, l->fb_seq */
	byte mseq;		/* l->mbox_seq */
	byte sattach;		/* l->servo_attach */
	byte wlast, wstill;	/* l->wd */
	byte fbad;		/* l->fb_bad (capped at WD) */
	bit  wprimed, seen, fresync, pending, first;
	byte rq;		/* ghost: the request pending */
	byte cyc, nposts, npoll;	/* bounds */
	byte pub, e, bb, x, y, b, cls, seq, peer, rc, ack;
	bit  took, gwhole, gnew, same;
	byte gsess;
	byte dr, target;	/* the drain */
	bit  ok_rt, ok_mb, err;

	do
	:: {
#ifdef OFFLINE_INIT
		!s_run;		/* supervisor.c: remoteproc says "offline" */
#endif
		/* ---- amp_linux_init ---- */
		d_step {
			g_sess++; l_sess = g_sess;
			ep = hdr_epoch + 1;	/* RD(&o->hdr.epoch) + 1, never 0 */
			if :: ep == 0 -> ep = 1 :: else fi;
			g_ep = ep
		};
		l_state = L_INIT;		/* invalidate first */
		hdr_ok = 0;			/* hdr.magic := 0 */
		/* every word but magic and the state, in layout order */
		hdr_epoch = 0;
		cmd_pub = 0;
		s_state = S_OFFLINE;
		s_epoch = 0;
		s_hb = 0;
		fb_pub = 0;
		s_attach = 0;
		cyc_sem = BUSY;		/* 0 is AMP_SEM_BUSY until set idle below */
		mbox_sem = BUSY;
		d_step { cmd_b[0] = 0; cmd_ep[0] = 0; cmd_e[0] = 0; gcmd_st[0] = G_NONE; cmd_wr(0) };
		d_step { cmd_b[1] = 0; cmd_ep[1] = 0; cmd_e[1] = 0; gcmd_st[1] = G_NONE; cmd_wr(1) };
		d_step { fb_b[0] = 0; fb_ep[0] = 0; fb_cs[0] = 0; fb_e[0] = 0;
			 gfb_st[0] = G_NONE; fb_wr(0); gfb_held[0] = 0 };
		d_step { fb_b[1] = 0; fb_ep[1] = 0; fb_cs[1] = 0; fb_e[1] = 0;
			 gfb_st[1] = G_NONE; fb_wr(1); gfb_held[1] = 0 };
		d_step { req_ok = 0; req_ep = 0; req_seq = 0 };
		d_step { rsp_ok = 0; rsp_ep = 0; rsp_seq = 0; rsp_proto = 0 };
		cyc_sem = IDLE;
		mbox_sem = IDLE;
		/* the header, one step: a reader of a half-written header fails
		 * its magic or CRC check */
		d_step { hdr_ok = 1; hdr_epoch = ep; g_hdr_sess = l_sess };
		d_step {
			l_state = L_READY;	/* WR_REL: the region is valid */
			/* *l = { 0 }, l->epoch, l->wd.limit */
			cseq = 0; fseq = 0; mseq = 0; sattach = 0; fbad = 0;
			wlast = 0; wstill = 0; wprimed = 0; seen = 0; fresync = 0; pending = 0;
			rq = 0; g_taken = 0; npoll = 0; gfb_rd = 0; gfb_dirty = 0;
#ifdef CHECK_ACKSEM
			g_tok = 0;
#endif
			dr = 0; target = 0; ok_rt = 0; ok_mb = 0; err = 0;
#ifdef OFFLINE_INIT
			s_off = 0;	/* servod: remoteproc starts the servo */
#endif
#ifdef NO_MBOX
			ok_mb = 1;
#endif
#ifdef NO_PERIODIC
			ok_rt = 1;
#endif
			skip
		};

		do
		:: !faults_off && cyc < NL ->
			l_cycle();
			d_step { took = 0; ack = 0; rc = 0 }
#ifndef NO_MBOX
		:: !faults_off && !pending && nposts < NR ->
			nposts++;
			l_post()
		:: !faults_off && pending ->
			l_poll()
		:: !faults_off && pending ->
			pending = 0	/* amp_linux_mbox_cancel: the caller's timeout */
#endif
#if K == 0
		:: cyc >= NL -> goto done	/* safety only: no drain */
#else
		:: !faults_off && cyc >= NL ->
			d_step {	/* the drain begins */
				faults_off = 1; lead = 0;
				/* what no step reads from here on */
				nlc = 0; nsc = 0; ncor = 0; cyc = 0; nposts = 0
			}
		:: faults_off ->
			if
			:: (ok_rt && ok_mb) || err -> goto done
			:: else
			fi;
			if
			:: dr >= K ->
#ifdef CHECK_RESUME
				printf("MSC: no resume in %d cycles: exchange %d mailbox %d\n", K, ok_rt, ok_mb);
				assert((ok_rt && ok_mb) || err);	/* false here: RESUME */
#endif
				goto done
			:: else
			fi;
			l_cycle();
			d_step {
				if
				:: target == 0 -> target = cseq
				:: else
				fi;
				if
				:: rc == R_OK && took && ack >= target && ack < 31 && ((g_taken >> ack) & 1) -> ok_rt = 1
				:: else
				fi;
				if
				:: rc == R_STALLED || rc == R_FEEDBACK || rc == R_PERR -> err = 1
				:: else
				fi;
				dr++; took = 0; ack = 0; rc = 0
			};
#ifndef NO_MBOX
			/* the mailbox thread: one post or poll per cycle; the
			 * caller's timeout ends a request after TMO polls */
			if
			:: pending ->
				l_poll();
				if
				:: pending && npoll + 1 >= TMO -> d_step { pending = 0; npoll = 0 }
				:: pending && npoll + 1 < TMO -> npoll++
				:: else
				fi
			:: !pending && !ok_mb -> l_post()
			:: else
			fi
#endif
#endif
		od
	} unless {
		l_kill ->
#ifdef OFFLINE_INIT
		/* servod starts again and initialises a region only once
		 * remoteproc has stopped the servo core */
		d_step { l_kill = 0; s_off = 1 }
#else
		l_kill = 0
#endif
	}
	od;
done:
	skip
}

/* ---------------- the servo ---------------- */
proctype Servo()
{
	bit  att;		/* link.c: attached */
	byte se;		/* s->epoch */
	byte ss;		/* ghost: the session attached to */
	byte cseq, fseq;	/* s->cmd_seq, s->fb_seq */
	bit  cresync;		/* s->cmd_resync */
	byte hbv;		/* s->heartbeat */
	byte pub, e, bb, x, b, cls, seq, sem;
	bit  valid, gwhole, gnew;
	byte gsess;
	byte mq, gq, gqs;

end_servo:
	do
	::
#ifdef OFFLINE_INIT
		atomic { !s_off -> s_run = 1 };	/* started by remoteproc */
#endif
		{
		d_step {	/* link_init: the private state starts at 0 */
			att = 0; se = 0; ss = 0; cseq = 0; fseq = 0; cresync = 0; hbv = 0;
			x = 0; gcmd_rd = 0; gcmd_dirty = 0
		};
end_loop:
		do
		:: (faults_off && lead <= 0) || (!faults_off && lead < LEAD) ->
			/* one cycle interrupt (link_cycle), then the background
			 * loop (link_poll); the interrupt counts once both are done */
			if
			:: !att ->
				/* link_poll: amp_servo_attach. Linux's state (acquire),
				 * then one copy of the header, checked (one step: Linux
				 * writes the header only while its state is INIT) */
				d_step {
					valid = (l_state == L_READY && hdr_ok && hdr_epoch != 0);
					se = (valid -> hdr_epoch : 0); ss = (valid -> g_hdr_sess : 0)
				};
				if
				:: !valid -> skip	/* PEER_ABSENT / LAYOUT: again later */
				:: else ->
					/* the servo's own line: fb_pub, the heartbeat; and
					 * the sequence words of both records: this attach
					 * continues after the newest sequence of all (a
					 * sequence written twice, by the crashed attach and
					 * by this one, defeats the seqlock: a reader that
					 * read the first seq_end takes the second payload
					 * half written) */
#ifdef MUTANT_NO_SKIP
					d_step { fseq = fb_pub; hbv = s_hb };
#else
					d_step {
						fseq = fb_pub; hbv = s_hb;
						newest(fseq, fb_b[0]); newest(fseq, fb_e[0]);
						newest(fseq, fb_b[1]); newest(fseq, fb_e[1])
					};
#endif
					d_step { cseq = cmd_pub; cresync = 1 };
					/* the records of earlier attaches: epoch word 0 */
					d_step { fb_ep[0] = 0; fb_wr(0); gfb_held[0] = 0 };
					d_step { fb_ep[1] = 0; fb_wr(1); gfb_held[1] = 0 };
					d_step { x = s_attach };
					d_step { s_attach = x + 1; x = 0 };
					s_state = S_RUNNING;
					s_epoch = se;		/* WR_REL */
					d_step {	/* link.c: attached = 1 */
						att = 1;
						/* ghost: nothing taken by this servo yet */
						if :: gcmd_st[0] == G_OLD -> gcmd_st[0] = G_NEW :: else fi;
						if :: gcmd_st[1] == G_OLD -> gcmd_st[1] = G_NEW :: else fi
					}
				fi;
				valid = 0
			:: att ->
				/* amp_servo_cycle_rx: 1. Linux's state (acquire), the
				 * header's epoch */
				d_step { x = l_state; bb = hdr_epoch; valid = (x == L_READY && bb == se); x = 0; bb = 0 };
				if
				:: !valid ->
					/* AMP_E_PEER_ABSENT; link.c: enter_safestop writes
					 * SAFESTOP in the line if the epoch is still ours,
					 * once Linux's first command in the attach was
					 * taken (before it: nothing written, attach again):
					 * either, here */
					d_step { bb = hdr_epoch };
					if
					:: bb == se -> if :: s_state = S_SAFESTOP :: skip fi
					:: else
					fi;
					d_step { att = 0; bb = 0 }
				:: else ->
					valid = 0;
#ifndef NO_PERIODIC
					/* 2. poll cmd_pub, then the semaphore, until one
					 * moved or the caller's timeout; the polls that find
					 * nothing are one step (the wait), then the last
					 * iteration's load of cmd_pub */
					pub = cmd_pub;
					if
					:: pub == cseq ->
						d_step { sem = cyc_sem };
						if
						:: sem != BUSY ->
							if
							:: skip		/* the timeout */
							:: atomic { (cmd_pub != cseq || cyc_sem == BUSY) -> pub = cmd_pub }
							fi
						:: else
						fi
					:: else
					fi;
					/* 3. amp__rx_record */
					d_step {
						sem = 0;
#ifdef MUTANT_NO_CMD_RESYNC
						classify(pub, cseq, 0, cls)
#else
						classify(pub, cseq, cresync, cls)
#endif
					};
					if
					:: cls == C_FRESH || cls == C_MISSED ->
						d_step { b = pub & 1; e = cmd_e[b]; gcmd_rd = b + 1; gcmd_dirty = 0 };
						d_step {
							x = cmd_ep[b];
							gwhole = (!gcmd_dirty && gcmd_st[b] != G_WRITING);
							gcmd_rd = 0; gcmd_dirty = 0;
							gnew = (gcmd_st[b] == G_NEW); gsess = gcmd_sess[b]
						};
						d_step {
							bb = cmd_b[b];
							if
							:: bb == e && e == pub && x == se ->
#ifdef CHECK_FRESH
								assert(gwhole);
								assert(gnew);
								assert(gsess == ss);
#endif
								take_cmd(b);
								cseq = pub; cresync = 0;
								if
								:: ss == l_sess && pub < 31 -> g_taken = g_taken | (1 << pub)
								:: else
								fi
							:: else
							fi;
							bb = 0; e = 0; x = 0; b = 0; gwhole = 0; gnew = 0; gsess = 0;
							pub = 0; cls = 0
						}
					:: else -> d_step { pub = 0; cls = 0 }
					fi;
					/* amp_servo_cycle_tx: 4. the feedback record */
					d_step {
						seq = fseq + 1; b = seq & 1;
						fb_b[b] = seq;
						gfb_st[b] = G_WRITING; fb_wr(b); gfb_held[b] = 0;
						gfb_sess[b] = ss; gfb_last = b
					};
					/* fb.cmd_seq: the last commands this servo took, 0
					 * before its first since the attach */
#ifdef MUTANT_ACK_ATTACH
					d_step { fb_ep[b] = se; fb_cs[b] = cseq; fb_wr(b) };
#else
					d_step { fb_ep[b] = se; fb_cs[b] = (cresync -> 0 : cseq); fb_wr(b) };
#endif
					d_step { fb_e[b] = seq; fb_wr(b); gfb_st[b] = G_NEW };
					/* the heartbeat, then fb_pub (one step: Linux reads
					 * fb_pub before the heartbeat in its cycle, so no
					 * interleaving between the two stores tells them
					 * apart) */
					d_step { hbv = (hbv + 1) % HBM; s_hb = hbv; fb_pub = seq; fseq = seq; seq = 0; b = 0 };
					/* 5. the token back if the servo holds it */
					d_step { sem = cyc_sem };
					if
					:: sem == BUSY -> d_step { cyc_sem = IDLE; sem = 0 }
					:: else -> sem = 0
					fi
#else
					d_step { hbv = (hbv + 1) % HBM; s_hb = hbv }
#endif
				fi
			fi;
#ifndef NO_MBOX
			/* link_poll: amp_servo_mbox_poll, the application's answer
			 * (amp_servo_mbox_respond) in the same pass */
			if
			:: att ->
				d_step { sem = mbox_sem };
				if
				:: sem == BUSY ->
					d_step {	/* amp__frame_recv: one copy */
						sem = 0;
						valid = (req_ok && req_ep == se);
						mq = req_seq; gq = greq_id; gqs = greq_sess
					};
					/* mbox_answer: amp__frame_put (the payload, then
					 * the header), AMP_E_PROTO for an invalid request */
					rsp_ok = 0;
					d_step {
						rsp_ok = 1; rsp_ep = se; rsp_seq = mq; rsp_proto = !valid;
						grsp_id = gq; grsp_sess = gqs
					};
					d_step { mbox_sem = IDLE; valid = 0; mq = 0; gq = 0; gqs = 0 }
				:: else -> sem = 0
				fi
			:: else
			fi;
#endif
			lead++
		od
#ifdef OFFLINE_INIT
	} unless { s_kill || s_off -> d_step { s_kill = 0; s_run = 0 } }
#else
	} unless { s_kill -> s_kill = 0 }
#endif
	od
}

/* ---------------- faults ---------------- */
/* a stray write of v to word w of fb[i]: another content, unless v is what
 * the word held */
inline stray_fb(w, i)
{
	if
	:: w != v -> gfb_held[i] = 0
	:: else
	fi;
	w = v
}

active proctype faults()
{
	byte v;

end_faults:
	do
	:: atomic { !faults_off && nlc < MAXLC && !l_kill -> nlc++; l_kill = 1 }
	:: atomic { !faults_off && nsc < MAXSC && !s_kill -> nsc++; s_kill = 1 }
	:: atomic { !faults_off && ncor < MAXCOR ->
		/* one value of each class the readers tell apart */
		ncor++;
		if
#ifndef NO_PERIODIC
		:: cyc_sem = BUSY
		:: cyc_sem = IDLE	/* or neither: both sides treat it as idle */
#endif
#ifndef NO_MBOX
		:: mbox_sem = BUSY
		:: mbox_sem = IDLE
		:: mbox_sem = GARB
#endif
		:: l_state = GARB	/* not READY */
		:: s_state = S_FAULT	/* OFFLINE or garbage too: all a peer error */
		:: s_epoch = 0		/* another epoch */
		:: s_epoch = g_ep	/* this epoch */
		:: hdr_ok = 0		/* magic, a field or the CRC */
		:: hdr_epoch = 0; hdr_ok = 0	/* an earlier epoch */
		:: hdr_epoch = g_ep + 1; hdr_ok = 0	/* a later one */
		:: s_attach = 0
		:: s_attach = s_attach + 1	/* as an attach would */
		:: s_hb = (s_hb + 1) % HBM	/* the servo's next beat */
		:: s_hb = (s_hb + 2) % HBM	/* another value */
#ifndef NO_PERIODIC
		/* the publication words: behind, 0, the next, far ahead */
		:: cmd_pub > 0 -> cmd_pub = cmd_pub - 1
		:: cmd_pub = 0
		:: cmd_pub = cmd_pub + 1
		:: cmd_pub = FAR
		:: fb_pub > 0 -> fb_pub = fb_pub - 1
		:: fb_pub = 0
		:: fb_pub = fb_pub + 1
		:: fb_pub = FAR
		/* a record's sequence and epoch words: a value that spoils the
		 * record (no sequence of the run, no epoch). A stray write that
		 * makes a record valid (the sequence or epoch it should have, at
		 * the moment it is read) forges it, as a stray write to its
		 * payload would: the records carry no checksum (the mailbox
		 * frames do), the seqlock guards against the writer only */
		:: cmd_b[0] = FAR
		:: cmd_b[1] = FAR
		:: cmd_e[0] = FAR
		:: cmd_e[1] = FAR
		:: cmd_ep[0] = 0
		:: cmd_ep[1] = 0
		:: v = FAR; stray_fb(fb_b[0], 0)
		:: v = FAR; stray_fb(fb_b[1], 1)
		:: v = FAR; stray_fb(fb_e[0], 0)
		:: v = FAR; stray_fb(fb_e[1], 1)
		:: v = 0; stray_fb(fb_ep[0], 0)
		:: v = 0; stray_fb(fb_ep[1], 1)
#endif
#ifndef NO_MBOX
		:: req_ok = 0		/* the frame fails its CRC */
		:: rsp_ok = 0
#endif
		fi;
		v = 0 }
	od
}

init
{
	atomic { run Linux(); run Servo() }
}
