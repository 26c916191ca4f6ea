*** Settings ***
Documentation     The cycle end to end on the ZynqMP, in one boot: rpu_app on
...               R5 0 (started by Linux's upstream xlnx_r5_remoteproc) and
...               servod on the A53 (PREEMPT_RT), paced by the two counters
...               of the PL's cycle timer on two PL-to-PS lines (the servo's
...               through the RPU's GIC, Linux's through the APU's GIC and
...               the cycle UIO driver), exchanging through
...               amp_lib's region in OCM. servod finds its remoteproc
...               through the mailbox's devicetree node. The exchange at
...               1 kHz with no cycle missed on either side (virtual time),
...               the real-time priorities, a parameter round trip, and an
...               operator's stop and start (a stop on request: no crash
...               reported, nothing restarted; the start re-attaches).
Resource          ../resources/zynqmp.resource
Resource          ../resources/servod.resource
Suite Setup       Boot Cycle Board
Suite Teardown    Quit Emulation

*** Variables ***
${FW}             rpu_app.elf

*** Keywords ***
Boot Cycle Board
    ${clock}=    Emulation Clock
    Set Suite Variable    ${CLOCK}    ${clock}
    Boot Board To Shell
    Start Servod
    Start Firmware Without Status Block    ${FW}
    Wait For Servod Log    parameter set loaded

Status
    ${out}=    Ampctl    status    expected_rc=any
    # several key=value pairs a line ("servo_state=RUNNING fault=0x0 (none) ...")
    ${d}=    Evaluate    dict(t.split('=', 1) for l in $out.splitlines() for t in l.split() if '=' in t)
    RETURN    ${d}

*** Test Cases ***
Both Cycles Come From The PL's Timer
    [Documentation]    Linux's cycle is counter 1 of the timer in the PL
    ...    (QEMU's, at 0x80000000 behind M_AXI_HPM0_LPD): its interrupt
    ...    register is what the cycle UIO device maps, its interrupt the
    ...    PL-to-PS line IRQ0[1] (GIC 122) at the APU's GIC, counting. The
    ...    servo's is counter 0 on IRQ0[0] (GIC 121) at the RPU's GIC.
    ${map}=    Execute Shell Command    for d in /sys/class/uio/uio*; do [ "$(cat $d/name)" = cycle-interrupt ] && echo "$(cat $d/maps/map0/addr) $(cat $d/maps/map0/offset)"; done; true
    Should Be Equal    ${map}    0x0000000080000000 0x58
    ${a}=    Execute Shell Command    grep cycle-interrupt /proc/interrupts
    Should Match Regexp    ${a}    \\s122\\s+Level\\s+cycle-interrupt
    Execute Shell Command    sleep 0.2
    ${b}=    Execute Shell Command    grep cycle-interrupt /proc/interrupts
    ${na}=    Evaluate    sum(int(w) for w in $a.split()[1:-4])
    ${nb}=    Evaluate    sum(int(w) for w in $b.split()[1:-4])
    Should Be True    ${nb} - ${na} >= 150    ${na} -> ${nb} interrupts in 0.2 s
    ${fw}=    Execute Shell Command    grep -m1 'cycle: irq' ${TRACE0}
    Should Contain    ${fw}    cycle: irq 121 (level)
    Should Contain    ${fw}    ttc 80000000 counter 0

servod Finds R5 0 Through The Mailbox's Devicetree Node
    [Documentation]    No board name in servod: the OCM mailbox's node
    ...    names the remoteproc (servoamp,remoteproc), the upstream
    ...    driver's ffe00000.r5f here.
    ${st}=    Status
    Should Be Equal    ${st}[remoteproc]    running
    Should Be Equal    ${st}[link]    attached
    Should Be Equal    ${st}[servo_state]    RUNNING
    ${ph}=    Execute Shell Command    od -An -tx1 /sys/class/uio/uio0/device/of_node/servoamp,remoteproc; od -An -tx1 ${RPROC}/device/of_node/phandle
    ${lines}=    Evaluate    [l.strip() for l in $ph.splitlines() if l.strip()]
    Should Be Equal    ${lines}[0]    ${lines}[1]

The Exchange Runs Every Cycle
    [Documentation]    Two guest seconds: every cycle handled on both sides,
    ...    nothing invalid, torn or stalled; on virtual time nothing missed.
    ${r}=    Exchange Window    2
    Exchange Should Run    ${r}
    Should Be True    ${r}[linux.cycles] >= 1900    ${r}[linux.cycles] cycles in 2 s

The Program Follows On Every Axis
    [Documentation]    servod's default program (a sine per axis) goes to
    ...    the R5 and the axes' feedback follows it.
    ${a}=    Status
    Execute Shell Command    sleep 0.5
    ${b}=    Status
    Should Not Be Equal    ${a}[program.cmd_inc]    ${b}[program.cmd_inc]
    ${cmd}=    Evaluate    [int(v) for v in $b['program.cmd_inc'].split(',')]
    ${act}=    Evaluate    [int(v) for v in $b['program.act_inc'].split(',')]
    FOR    ${c}    ${x}    IN ZIP    ${cmd}    ${act}
        Should Be True    abs(${c} - ${x}) <= 50    command ${c} vs actual ${x}
    END

Real-Time Priorities As On The Zynq-7000
    [Documentation]    The cycle interrupt bound by servoamp's UIO driver, its
    ...    thread at SCHED_FIFO 81 above servod's cycle thread (FIFO 80).
    ${uio}=    Execute Shell Command    for d in /sys/class/uio/uio*; do echo "$(cat $d/name): $(cat $d/version)"; done
    Should Contain    ${uio}    cycle-interrupt: servoamp-cycle-uio 1
    ${thr}=    Execute Shell Command    for p in /proc/[0-9]*/task/[0-9]*; do s=$(cut -d' ' -f40,41 $p/stat 2>/dev/null); case $s in ''|*' 0') ;; *) echo "$(cat $p/comm) $s";; esac; done; true
    Log    ${thr}
    Should Match Regexp    ${thr}    (?m)^irq/\\d+-cycle-\\S* 81 1$
    Should Match Regexp    ${thr}    (?m)^servod 80 1$

A Parameter Round Trip
    Ampctl    param set pos_kp 61.5
    ${out}=    Ampctl    param get pos_kp
    Should Contain    ${out}    61.5

An Operator's Stop Is Final, A Start Attaches Again
    [Documentation]    The upstream driver powers the core down without
    ...    asking the firmware: servod sees remoteproc offline, counts no
    ...    crash and restarts nothing; the next start attaches in a new
    ...    epoch with the parameters restored.
    Execute Shell Command    echo stop > ${RPROC}/state
    Remoteproc State Should Be    offline
    Wait For Servod Log    waiting for the servo    2
    Execute Shell Command    sleep 1
    ${st}=    Status
    Should Be Equal    ${st}[remoteproc]    offline
    Should Be Equal    ${st}[recoveries]    0
    # no stall taken for a crash: this driver has no report_crash, so a
    # stall would be logged as servod's own record ("... restarting the
    # firmware (servod's record ...)"), never "reporting a crash"
    ${stall}=    Servod Log Count    restarting the firmware
    Should Be Equal As Integers    ${stall}    0
    ${crash}=    Servod Log Count    reporting a crash
    Should Be Equal As Integers    ${crash}    0
    Start Firmware Without Status Block    ${FW}
    Wait For Servod Log    parameter set loaded    2
    ${st}=    Status
    Should Be Equal    ${st}[link]    attached
    ${out}=    Ampctl    param get pos_kp
    Should Contain    ${out}    61.5
    ${r}=    Exchange Window    1
    Exchange Should Run    ${r}
