*** Settings ***
Documentation     servod's recovery on the ZynqMP, in one boot, through the
...               upstream xlnx_r5_remoteproc, which has no report_crash
...               (servod says so once and keeps the stall as its own
...               record) and disables remoteproc's own recovery at probe:
...               servod restarts rpu_app on R5 0 through remoteproc's
...               state (stop: the driver powers the core down through
...               TF-A and the PMU stand-in; start). servod runs with its
...               default bounds (3 restarts within 60 s, then the fault
...               latch). In guest time (-icount): a hang and a fault
...               (the R5 waits in WFI) are detected within wd_limit
...               cycles and recovered within wd_limit + 1 s, with the
...               parameters set before; a firmware that fails after
...               every attach is latched after the limit and `ampctl
...               fault reset` brings it back; an operator's stop and
...               start, three times, is no crash and counts nothing
...               towards the latch. The Zynq-7000's versions:
...               tests/robot/test_recovery_board.py,
...               test_operator_stop_board.py, test_recovery_stress.py
...               (their netboard boots the Zynq-7000 only so far).
Resource          ../resources/zynqmp.resource
Resource          ../resources/servod.resource
Suite Setup       Boot Recovery Board
Suite Teardown    Quit Emulation

*** Variables ***
${FW}             rpu_app.elf
# servod's default wd_limit (the parameter's default): virtual time, so no
# host hiccup can trip it
${WD_LIMIT}       10
${KP}             61.5

*** Keywords ***
Boot Recovery Board
    ${clock}=    Emulation Clock
    Set Suite Variable    ${CLOCK}    ${clock}
    Boot Board To Shell
    Start Servod    ${EMPTY}
    Start Firmware Without Status Block    ${FW}
    Wait For Servod Log    parameter set loaded
    ${out}=    Ampctl    param get wd_limit
    Should Contain    ${out}    ${WD_LIMIT}

Stats Latched
    [Documentation]    `ampctl stats` while the fault is latched (exit 3).
    ${out}=    Ampctl    stats    expected_rc=3
    ${d}=    Evaluate    {l.split('=', 1)[0]: l.split('=', 1)[1] for l in $out.splitlines() if '=' in l}
    RETURN    ${d}

Status
    ${out}=    Ampctl    status    expected_rc=any
    ${d}=    Evaluate    dict(t.split('=', 1) for l in $out.splitlines() for t in l.split() if '=' in t)
    RETURN    ${d}

Parameter Should Be Restored
    ${out}=    Ampctl    param get pos_kp
    Should Contain    ${out}    ${KP}

A Failure Is Recovered
    [Documentation]    ${command} makes rpu_app fail; the stall is seen
    ...    within wd_limit cycles of the last heartbeat and the servo is
    ...    back within wd_limit + 1 s of the command (guest time), with
    ...    the parameter set; no crash reported to remoteproc.
    [Arguments]    ${command}
    ${n}=    Servod Log Count    recovery complete
    ${a}=    Stats
    Run And Wait For Servod Log    cat /proc/uptime > /tmp/hang.t; ${command}    recovery complete    ${n + 1}
    ${b}=    Stats
    ${up}=    Execute Shell Command    cat /tmp/hang.t
    ${hang}=    Evaluate    float($up.split()[0])
    ${stalled}=    Servod Log Times    restarting the firmware (servod's record
    ${back}=    Servod Log Times    recovery complete
    ${cycles}=    Set Variable    ${b}[linux.last_stall_cycles]
    ${took}=    Evaluate    round($back[-1] - $hang, 3)
    Log    ${command}: asked at ${hang} s, stall seen at ${stalled}[-1] s (${cycles} cycles after the last heartbeat), recovered at ${back}[-1] s (guest): ${took} s    console=True
    Should Be True    ${cycles} <= ${WD_LIMIT} + 1    stall seen ${cycles} cycles after the last heartbeat
    Should Be True    ${took} <= ${WD_LIMIT} / 1000 + 1.0 + 0.01    recovered ${took} s after the command
    ${d}=    Delta    ${a}    ${b}    linux.recoveries
    Should Be Equal As Integers    ${d}    1
    Should Be Equal    ${b}[servo.state]    RUNNING
    Remoteproc State Should Be    running
    Parameter Should Be Restored
    ${crash}=    Servod Log Count    reporting a crash
    Should Be Equal As Integers    ${crash}    0
    ${err}=    Servod Log Count    all the same
    Should Be Equal As Integers    ${err}    0

*** Test Cases ***
servod Says Once What It Does Without report_crash
    [Documentation]    The upstream driver has no device/report_crash and
    ...    has disabled remoteproc's own recovery: servod writes neither,
    ...    says so once, and restarts through the state file.
    Execute Shell Command    test ! -e ${RPROC}/device/report_crash
    ${rec}=    Execute Shell Command    cat ${RPROC}/recovery
    Should Be Equal    ${rec}    disabled
    ${n}=    Servod Log Count    no device/report_crash
    Should Be Equal As Integers    ${n}    1
    ${n}=    Servod Log Count    remoteproc's own recovery is disabled
    Should Be Equal As Integers    ${n}    1
    Ampctl    param set pos_kp ${KP}
    Parameter Should Be Restored

A Hang Is Detected And Recovered With The Parameters
    [Documentation]    `ampctl debug hang`: cycle work and heartbeat stop.
    A Failure Is Recovered    ampctl debug hang
    ${r}=    Exchange Window    1
    Exchange Should Run    ${r}

A Fault Is Detected And Recovered With The Parameters
    [Documentation]    `ampctl debug fault`: the servo line says FAULT,
    ...    then rpu_app waits in WFI (no stop contract on the R5) until the
    ...    driver's power-down, which servod's restart asks for.
    A Failure Is Recovered    ampctl debug fault
    ${r}=    Exchange Window    1
    Exchange Should Run    ${r}

A Firmware That Fails After Every Attach Is Latched, fault reset Brings It Back
    [Documentation]    rpu_app is hung again at each "parameter set
    ...    loaded": 3 restarts within 60 s, the fourth stall latches the
    ...    fault (firmware stopped, `ampctl status` exits 3 and says why),
    ...    nothing restarted while latched; the operator's reset restarts
    ...    it with the parameter set.
    Ampctl    fault reset
    ${n}=    Servod Log Count    the axes disabled until
    ${a}=    Stats
    Execute Shell Command    touch /tmp/hangloop.on; ( ( last=$(grep -c 'parameter set loaded' ${LOG}); while [ -e /tmp/hangloop.on ]; do n=$(grep -c 'parameter set loaded' ${LOG}); if [ $n -gt $last ]; then last=$n; ampctl debug hang >/dev/null 2>&1; fi; sleep 0.01; done ) >/dev/null 2>&1 & )
    Run And Wait For Servod Log    ampctl debug hang    the axes disabled until    ${n + 1}
    Execute Shell Command    rm -f /tmp/hangloop.on
    ${st}=    Ampctl    status    expected_rc=3
    Should Contain    ${st}    fault latched (servo stalled (heartbeat still for ${WD_LIMIT} cycles); 3 restarts within 60 s (limit 3))
    Should Contain    ${st}    latched=1
    Should Contain    ${st}    session=fault
    Remoteproc State Should Be    offline
    ${b}=    Stats Latched
    ${d}=    Delta    ${a}    ${b}    linux.recoveries
    Should Be Equal As Integers    ${d}    3
    ${d}=    Delta    ${a}    ${b}    linux.latches
    Should Be Equal As Integers    ${d}    1
    Execute Shell Command    sleep 2
    ${c}=    Stats Latched
    ${d}=    Delta    ${b}    ${c}    linux.recoveries
    Should Be Equal As Integers    ${d}    0
    Remoteproc State Should Be    offline
    ${n}=    Servod Log Count    recovery complete
    Run And Wait For Servod Log    ampctl fault reset > /tmp/reset.out 2>&1    recovery complete    ${n + 1}
    ${out}=    Execute Shell Command    cat /tmp/reset.out
    Should Contain    ${out}    fault reset: restarting the servo
    ${last}=    Execute Shell Command    grep 'recovery complete' ${LOG} | tail -n 1
    Should Contain    ${last}    after the operator's fault reset
    ${st}=    Status
    Should Be Equal    ${st}[latched]    0
    Should Be Equal    ${st}[link]    attached
    Remoteproc State Should Be    running
    Parameter Should Be Restored
    ${r}=    Exchange Window    1
    Exchange Should Run    ${r}

An Operator's Stop During Run Is Not A Crash, Three Times
    [Documentation]    Stop and start through remoteproc's state three
    ...    times within the latch's window (limit 3): the driver powers R5 0
    ...    down without asking the firmware; servod sees remoteproc offline,
    ...    reports no stall, restarts nothing, counts nothing, and each start
    ...    attaches with the parameter set.
    Ampctl    fault reset
    ${a}=    Stats
    ${stalls}=    Servod Log Count    servo stalled
    FOR    ${round}    IN RANGE    3
        ${w}=    Servod Log Count    waiting for the servo
        Run And Wait For Servod Log    echo stop > ${RPROC}/state    waiting for the servo    ${w + 1}
        Remoteproc State Should Be    offline
        ${p}=    Servod Log Count    parameter set loaded
        Run And Wait For Servod Log    echo start > ${RPROC}/state    parameter set loaded    ${p + 1}
        Remoteproc State Should Be    running
        Parameter Should Be Restored
    END
    Execute Shell Command    sleep 1
    ${b}=    Stats
    ${d}=    Delta    ${a}    ${b}    linux.recoveries
    Should Be Equal As Integers    ${d}    0
    ${d}=    Delta    ${a}    ${b}    linux.latches
    Should Be Equal As Integers    ${d}    0
    ${n}=    Servod Log Count    servo stalled
    Should Be Equal As Integers    ${n}    ${stalls}
    ${st}=    Status
    Should Be Equal    ${st}[latched]    0
    Should Be Equal    ${st}[link]    attached
    ${r}=    Exchange Window    1
    Exchange Should Run    ${r}
