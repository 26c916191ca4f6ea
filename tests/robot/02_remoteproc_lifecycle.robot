*** Settings ***
Documentation     Load, start, stop and restart the servo core through
...               remoteproc sysfs (test firmware of tests/robot/fixtures;
...               rpu_app too when it has been built): RUN! and PRKD in OCM,
...               banner on UART1 and in trace0, 50 stop/start cycles, start
...               and stop timeouts. One QEMU boot for the whole suite.
Resource          resources/servoamp.resource
Suite Setup       Boot Board To Shell
Suite Teardown    Quit Emulation

*** Variables ***
${FW_RSC}         test-fw-rsc.elf
${FW_NORSC}       test-fw-norsc.elf
${CYCLES}         50

*** Test Cases ***
Firmware With A Resource Table Starts
    Clear Terminal Tester Report    ${SERVO_UART}
    Start Firmware    ${FW_RSC}
    Wait For Line On Uart    servoamp test-fw rsc: running    testerId=${SERVO_UART}
    ${hb}=    Firmware Symbol    ${FW_RSC}    heartbeat
    Heartbeat Should Advance    ${hb}
    Word Should Be    ${CONTROL_WORD}    0
    ${log}=    Execute Shell Command    dmesg | grep "RUN! after" | tail -n 1
    Log    echo start -> RUN!: ${log}    console=True

Trace0 Shows The Banner
    ${trace}=    Execute Shell Command    cat ${TRACE0}
    Should Contain    ${trace}    servoamp test-fw rsc: running

Firmware Stops Cooperatively
    Stop Firmware
    Wait For Line On Uart    servoamp test-fw rsc: parking    testerId=${SERVO_UART}
    Word Should Be    ${CONTROL_WORD}    ${STOP}
    Execute Shell Command    test ! -e ${TRACE0}

Firmware Starts Again After A Stop
    Start Firmware    ${FW_RSC}
    Wait For Line On Uart    servoamp test-fw rsc: running    testerId=${SERVO_UART}
    Stop Firmware
    Wait For Line On Uart    servoamp test-fw rsc: parking    testerId=${SERVO_UART}

Firmware Without A Resource Table Boots Too
    Start Firmware    ${FW_NORSC}
    Wait For Line On Uart    servoamp test-fw norsc: running    testerId=${SERVO_UART}
    Dmesg Should Contain    ${FW_NORSC} has no resource table
    Execute Shell Command    test ! -e ${TRACE0}
    ${hb}=    Firmware Symbol    ${FW_NORSC}    heartbeat
    Heartbeat Should Advance    ${hb}
    Stop Firmware
    Wait For Line On Uart    servoamp test-fw norsc: parking    testerId=${SERVO_UART}

Fifty Stop Start Cycles In One Boot
    [Documentation]    Every cycle is checked in the guest (start and stop
    ...    succeed, the state reads running then offline, the status word
    ...    reads RUN! then PRKD) and on the host (one banner and one goodbye
    ...    per cycle on UART1).
    Select Firmware    ${FW_RSC}
    Clear Terminal Tester Report    ${SERVO_UART}
    ${script}=    Catenate    SEPARATOR=${SPACE}
    ...    ok=0; bad=0; for i in $(seq ${CYCLES}); do
    ...    if echo start > ${RPROC}/state && [ "$(cat ${RPROC}/state)" = running ]
    ...    && [ "$(devmem ${STATUS_WORD} 32)" = ${RUNNING_HEX} ]
    ...    && echo stop > ${RPROC}/state && [ "$(cat ${RPROC}/state)" = offline ]
    ...    && [ "$(devmem ${STATUS_WORD} 32)" = ${PARKED_HEX} ];
    ...    then ok=$((ok+1)); else bad=$((bad+1)); echo "cycle $i failed"; fi; done;
    ...    echo "cycles ok=$ok bad=$bad"
    ${t0}=    Evaluate    time.time()    modules=time
    ${out}=    Execute Shell Command    ${script}    timeout=120 s
    ${t1}=    Evaluate    time.time()    modules=time
    Should Contain    ${out}    cycles ok=${CYCLES} bad=0
    FOR    ${i}    IN RANGE    ${CYCLES}
        Wait For Line On Uart    servoamp test-fw rsc: running    testerId=${SERVO_UART}    timeout=5 s
        Wait For Line On Uart    servoamp test-fw rsc: parking    testerId=${SERVO_UART}    timeout=5 s
    END
    ${ups}=    Execute Shell Command    dmesg | grep -c "remote processor servo-cpu1 is now up"
    Should Be True    ${ups} >= ${CYCLES}
    ${secs}=    Evaluate    ${t1} - ${t0}
    ${secs}=    Evaluate    round(${secs}, 2)
    Log    ${CYCLES} start/stop cycles took ${secs} s (host)    console=True
    Remoteproc State Should Be    offline

A Firmware That Never Reports RUN! Is Refused And Parked
    Clear Terminal Tester Report    ${SERVO_UART}
    Start Should Be Refused    test-fw-mute.elf
    Dmesg Should Contain    did not report RUN! within
    Wait For Line On Uart    servoamp test-fw mute: parking    testerId=${SERVO_UART}
    Word Should Be    ${STATUS_WORD}    ${PARKED}
    Start Firmware    ${FW_RSC}
    Stop Firmware

Unloading The Driver Stops The Firmware
    [Documentation]    rmmod while running shuts the servo core down through
    ...    the same cooperative stop; a reloaded driver starts it again.
    Start Firmware    ${FW_RSC}
    Execute Shell Command    rmmod zynq_servo_rproc
    Word Should Be    ${STATUS_WORD}    ${PARKED}    timeout=2 s
    Word Should Be    ${BOOT_REGISTER}    0
    Execute Shell Command    test ! -e ${RPROC}
    Execute Shell Command    insmod /lib/modules/zynq_servo_rproc.ko
    ${name}=    Execute Shell Command    cat ${RPROC}/name
    Should Be Equal    ${name}    servo-cpu1
    Remoteproc State Should Be    offline
    Start Firmware    ${FW_RSC}
    Stop Firmware

rpu_app Starts And Stops
    [Documentation]    The servo firmware (rpu_app/), when it has been built
    ...    into build/rpu_app/: banner "servoamp rpu_app" on UART1.
    ${have}=    Firmware In Image    rpu_app.elf
    Skip If    not ${have}    rpu_app.elf has not been built (build/rpu_app/)
    Clear Terminal Tester Report    ${SERVO_UART}
    Start Firmware    rpu_app.elf
    Wait For Line On Uart    servoamp rpu_app    testerId=${SERVO_UART}
    Stop Firmware
    Start Firmware    rpu_app.elf
    Stop Firmware

A Firmware That Ignores STOP Cannot Be Stopped And Nothing Is Loaded After It
    [Documentation]    Last test of the suite on purpose. The park request
    ...    times out after 500 ms and the driver writes the SLCR CPU1 reset
    ...    (A9_CPU_RST_CTRL), which QEMU only stores: CPU1 keeps running this
    ...    firmware (its heartbeat still moves, 'RUN!' stays). The stop is an
    ...    error that says why, the state stays running; a reloaded driver
    ...    finds 'RUN!', cannot park the firmware either, and refuses to load
    ...    anything, with the reason. Linux goes on.
    Start Firmware    test-fw-deaf.elf
    ${hb}=    Firmware Symbol    test-fw-deaf.elf    heartbeat
    Execute Shell Command    dmesg -c > /dev/null
    Execute Shell Command    echo stop > ${RPROC}/state    expected_rc=1
    Remoteproc State Should Be    running
    Dmesg Should Contain    firmware did not park within 500 ms (status ${RUNNING_LC}): resetting CPU1
    Dmesg Should Contain    CPU1 reset through SLCR A9_CPU_RST_CTRL
    Dmesg Should Contain    CPU1 not confirmed stopped: status ${RUNNING_LC}, not 'PRKD', 50 ms after the SLCR reset
    Dmesg Should Contain    nothing will be loaded until CPU1 parks
    ${rst}=    Read Word    0xf8000244
    Should Be Equal As Integers    ${rst}    0
    Heartbeat Should Advance    ${hb}
    Word Should Be    ${STATUS_WORD}    ${RUNNING}
    Execute Shell Command    echo stop > ${RPROC}/state    expected_rc=1
    Remoteproc State Should Be    running
    Execute Shell Command    rmmod zynq_servo_rproc
    Execute Shell Command    dmesg -c > /dev/null
    Execute Shell Command    insmod /lib/modules/zynq_servo_rproc.ko
    Dmesg Should Contain    status word reads 'RUN!': a firmware may still run on CPU1, asking it to park
    Dmesg Should Contain    CPU1 not confirmed stopped: status ${RUNNING_LC}
    Remoteproc State Should Be    offline
    Word Should Be    ${STATUS_WORD}    ${RUNNING}
    Execute Shell Command    dmesg -c > /dev/null
    Start Should Be Refused    ${FW_RSC}
    Dmesg Should Contain    ${FW_RSC}: not loaded: CPU1 is not known to be parked or reset
    Heartbeat Should Advance    ${hb}
    ${out}=    Execute Shell Command    echo alive
    Should Be Equal    ${out}    alive
