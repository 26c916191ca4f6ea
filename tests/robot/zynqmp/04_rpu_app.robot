*** Settings ***
Documentation     rpu_app, the servo firmware, on R5 0 of the ZynqMP (platform
...               rpu_app/platform/zynqmp_r5: PMSAv7 MPU, vectors in ATCM,
...               the RPU's own GIC, the core's cycle counter as time base),
...               started and stopped by Linux's upstream xlnx_r5_remoteproc:
...               its banner and statistics on UART1 and in trace0, the cycle
...               from the PL's timer through the RPU GIC at 1 kHz without a
...               miss, the nesting and VFP self-tests. servod is not on this board yet
...               (issue 35): the link waits for its peer. One QEMU boot.
Resource          ../resources/zynqmp.resource
Suite Setup       Boot Board To Shell
Suite Teardown    Quit Emulation

*** Variables ***
${STATS}          stats cycle=(\\d+) guest_us=\\d+ period_min_ns=(\\d+) period_max_ns=(\\d+) overruns=(\\d+) missed=(\\d+) nest_max=\\d+ nest_test_ok=(\\d+) nest_test_fail=(\\d+) fpu_test_ok=(\\d+) fpu_test_fail=(\\d+)

*** Test Cases ***
rpu_app Starts On R5 0
    Clear Terminal Tester Report    ${SERVO_UART}
    Start Firmware Without Status Block    rpu_app.elf
    ${banner}=    Wait For Line On Uart    servoamp rpu_app    testerId=${SERVO_UART}
    Should Contain    ${banner}    board=zynqmp_qemu
    ${cpu}=    Wait For Line On Uart    no VBAR: vectors at 0x0    testerId=${SERVO_UART}
    Should Contain    ${cpu}    mpu=on (PMSAv7
    # the cycle: counter 0 of the PL's timer (0x80000000), on the PL-to-PS
    # line IRQ0[0] (SPI 89, GIC 121) taken at the RPU's GIC
    ${cyc}=    Wait For Line On Uart    cycle: irq    testerId=${SERVO_UART}
    Should Contain    ${cyc}    cycle: irq 121 (level)
    Should Contain    ${cyc}    ttc 80000000 counter 0
    Wait For Line On Uart    running: no stop word    testerId=${SERVO_UART}

The Cycle Runs At 1 kHz Without A Miss
    [Documentation]    Two statistics lines (1000 cycles each): periods of
    ...    1 ms from the core's own cycle counter, no overrun, no missed
    ...    cycle, and the nesting and VFP self-tests pass (an SGI of the
    ...    RPU GIC preempting the cycle handler).
    FOR    ${n}    IN    1000    2000
        ${line}=    Wait For Line On Uart    stats cycle=${n} guest_us    testerId=${SERVO_UART}    timeout=30 s
        ${m}=    Get Regexp Matches    ${line}    ${STATS}    1    2    3    4    5    6    7    8    9
        Log    ${line}    console=True
        ${cyc}    ${pmin}    ${pmax}    ${ovr}    ${mis}    ${nok}    ${nfail}    ${fok}    ${ffail}=    Set Variable    @{m}[0]
        Should Be True    999000 <= ${pmin} <= ${pmax} <= 1001000    periods ${pmin}..${pmax} ns
        Should Be Equal    ${ovr}${mis}    00    overruns ${ovr}, missed ${mis}
        Should Be Equal    ${nfail}${ffail}    00    nesting/VFP self-test failed
        Should Be True    ${nok} >= 1 and ${fok} >= 1
    END

Trace0 Has The Log
    ${trace}=    Execute Shell Command    cat ${TRACE0}
    Should Contain    ${trace}    servoamp rpu_app
    Should Contain    ${trace}    stats cycle=1000

Stop And Start Ten Times
    [Documentation]    The upstream driver's stop powers the core down
    ...    (no cooperative stop); every start runs the firmware from its
    ...    reset again: a banner each time, cycles counted from 0.
    FOR    ${i}    IN RANGE    10
        Execute Shell Command    echo stop > ${RPROC}/state
        Remoteproc State Should Be    offline
        R5 Should Be Held    ${R5_0}
        Clear Terminal Tester Report    ${SERVO_UART}
        Execute Shell Command    echo start > ${RPROC}/state
        Remoteproc State Should Be    running
        Wait For Line On Uart    servoamp rpu_app    testerId=${SERVO_UART}
        Wait For Line On Uart    running: no stop word    testerId=${SERVO_UART}
    END
    Wait For Line On Uart    stats cycle=1000 guest_us    testerId=${SERVO_UART}    timeout=30 s
    Execute Shell Command    echo stop > ${RPROC}/state
    Remoteproc State Should Be    offline

rpu_app Without A Resource Table Starts Too
    Clear Terminal Tester Report    ${SERVO_UART}
    Start Firmware Without Status Block    rpu_app-norsc.elf
    Wait For Line On Uart    servoamp rpu_app    testerId=${SERVO_UART}
    Dmesg Should Contain    no resource table found
    Execute Shell Command    test ! -e ${TRACE0}
    Wait For Line On Uart    stats cycle=1000 guest_us    testerId=${SERVO_UART}    timeout=30 s
    Execute Shell Command    echo stop > ${RPROC}/state
    Remoteproc State Should Be    offline

