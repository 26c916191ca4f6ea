*** Settings ***
Documentation     Start, stop and restart the R5s through Linux's upstream
...               xlnx_r5_remoteproc (remoteproc sysfs), with the test
...               firmware of tests/zynqmp/fixtures: from TCM (low vectors)
...               with and without a resource table, from DDR with its
...               vectors in TCM, with vectors in OCM (high vectors), on
...               either R5; banner on UART1 and in trace0, a TTC tick through
...               the RPU's GIC, 50 stop/start cycles. One QEMU boot.
Resource          ../resources/zynqmp.resource
Suite Setup       Boot Board To Shell
Suite Teardown    Quit Emulation

*** Variables ***
${FW_RSC}         r5-fw-rsc.elf
${CYCLES}         50

*** Test Cases ***
The Default Firmware Starts
    [Documentation]    Nothing written to ``firmware``: the driver loads
    ...    rproc-ffe00000.r5f-fw (the initramfs has the TCM test firmware
    ...    under that name), as ``west emu -b zynqmp_qemu`` does.
    Clear Terminal Tester Report    ${SERVO_UART}
    Start Selected Firmware
    Wait For Line On Uart    servoamp r5-fw rsc: running    testerId=${SERVO_UART}
    Word Should Be    ${VECTOR_WORD}    0
    Heartbeat Should Advance    ${HEARTBEAT}

The Firmware Takes The TTC Tick Through The RPU GIC
    [Documentation]    TTC0 counter 0 interrupts at 1 kHz (SPI 36 into the
    ...    RPU's PL390, to the core's own CPU interface); the firmware counts
    ...    the interrupts it takes. One guest second: 1000 ticks.
    ${out}=    Execute Shell Command    devmem ${TICKS} 32; sleep 1; devmem ${TICKS} 32
    ${n}=    Evaluate    int($out.split()[1], 16) - int($out.split()[0], 16)
    Log    TTC ticks in a guest second: ${n}    console=True
    Should Be True    950 <= ${n} <= 1050    ${n} ticks in one guest second, not 1000

Trace0 Shows The Banner
    ${trace}=    Execute Shell Command    cat ${TRACE0}
    Should Contain    ${trace}    servoamp r5-fw rsc: running

The Firmware Stops
    Stop Firmware
    Execute Shell Command    test ! -e ${TRACE0}

Firmware Without A Resource Table Starts Too
    Clear Terminal Tester Report    ${SERVO_UART}
    Start Firmware    r5-fw-norsc.elf
    Wait For Line On Uart    servoamp r5-fw norsc: running    testerId=${SERVO_UART}
    Dmesg Should Contain    no resource table found
    Execute Shell Command    test ! -e ${TRACE0}
    Heartbeat Should Advance    ${HEARTBEAT}
    Stop Firmware

Firmware In DDR With Its Vectors In TCM
    [Documentation]    Code, data, resource table and trace buffer in the
    ...    DDR carveout (0x3ed00000); the low vectors in ATCM jump there.
    Clear Terminal Tester Report    ${SERVO_UART}
    Start Firmware    r5-fw-ddr.elf
    Wait For Line On Uart    servoamp r5-fw ddr: running    testerId=${SERVO_UART}
    ${trace}=    Execute Shell Command    cat ${TRACE0}
    Should Contain    ${trace}    servoamp r5-fw ddr: running
    Word Should Be    ${VECTOR_WORD}    0
    Heartbeat Should Advance    ${HEARTBEAT}
    Stop Firmware

Firmware With Its Vectors In OCM Starts From The Low Vectors
    [Documentation]    The ELF's entry is 0xffff0000 (a vector table in OCM,
    ...    the driver's "sram" carveout; another in ATCM), so the driver asks
    ...    for high vectors (PM_RPU_BOOTMEM_HIVEC). In Linux 6.12 that
    ...    request is 1 | set-address 1 = the low-vector request: TF-A passes
    ...    address 0 to the PMU, and the PMU firmware (our stand-in as the
    ...    real one) clears VINITHI. The core starts at 0x0, as on hardware
    ...    (docs/boot-flow-zynqmp.md, "Vectors"); the OCM table is loaded but
    ...    not used.
    Clear Terminal Tester Report    ${SERVO_UART}
    Start Firmware    r5-fw-hivec.elf
    Wait For Line On Uart    servoamp r5-fw hivec: running    testerId=${SERVO_UART}
    Word Should Be    ${VECTOR_WORD}    0
    ${hivec}=    Board Value    servo    high_vectors
    ${first}=    Read Word    ${hivec}
    Should Not Be Equal As Integers    ${first}    0    the OCM vector table was not loaded
    Stop Firmware

Fifty Stop Start Cycles In One Boot
    [Documentation]    Every cycle is checked in the guest (start and stop
    ...    succeed, the state reads running then offline, the firmware wrote
    ...    'R5UP') and on the host (one banner per cycle on UART1).
    Select Firmware    ${FW_RSC}
    Clear Terminal Tester Report    ${SERVO_UART}
    ${r5up}=    Convert To Hex    ${R5UP}    prefix=0x    length=8
    ${script}=    Catenate    SEPARATOR=${SPACE}
    ...    ok=0; bad=0; for i in $(seq ${CYCLES}); do devmem ${MAGIC_WORD} 32 0;
    ...    if echo start > ${RPROC}/state && [ "$(cat ${RPROC}/state)" = running ]
    ...    && sleep 0.01 && [ "$(devmem ${MAGIC_WORD} 32)" = ${r5up} ]
    ...    && echo stop > ${RPROC}/state && [ "$(cat ${RPROC}/state)" = offline ];
    ...    then ok=$((ok+1)); else bad=$((bad+1)); echo "cycle $i failed"; fi; done;
    ...    echo "cycles ok=$ok bad=$bad"
    ${t0}=    Evaluate    time.time()    modules=time
    ${out}=    Execute Shell Command    ${script}    timeout=300 s
    ${t1}=    Evaluate    time.time()    modules=time
    Should Contain    ${out}    cycles ok=${CYCLES} bad=0
    FOR    ${i}    IN RANGE    ${CYCLES}
        Wait For Line On Uart    servoamp r5-fw rsc: running    testerId=${SERVO_UART}    timeout=5 s
    END
    ${ups}=    Execute Shell Command    dmesg | grep -c "remote processor ffe00000.r5f is now up"
    Should Be True    ${ups} >= ${CYCLES}
    ${secs}=    Evaluate    round(${t1} - ${t0}, 2)
    Log    ${CYCLES} start/stop cycles took ${secs} s (host)    console=True
    Remoteproc State Should Be    offline
    R5 Should Be Held    ${R5_0}

The Second R5 Starts And Stops
    [Documentation]    Split mode: R5 1 (remoteproc1, its own TCM) runs the
    ...    same TCM firmware; its tick goes to its own GIC CPU interface.
    ${r1}=    Set Variable    /sys/class/remoteproc/remoteproc1
    Clear Status Block
    Clear Terminal Tester Report    ${SERVO_UART}
    Execute Shell Command    echo ${FW_RSC} > ${r1}/firmware; echo start > ${r1}/state
    ${state}=    Execute Shell Command    cat ${r1}/state
    Should Be Equal    ${state}    running
    Wait For Line On Uart    servoamp r5-fw rsc: running    testerId=${SERVO_UART}
    Word Should Be    ${MAGIC_WORD}    ${R5UP}    timeout=2 s
    Heartbeat Should Advance    ${TICKS}
    R5 Should Be Held    ${R5_0}
    Execute Shell Command    echo stop > ${r1}/state
    ${state}=    Execute Shell Command    cat ${r1}/state
    Should Be Equal    ${state}    offline
    R5 Should Be Held    ${R5_1}
    Heartbeat Should Stand Still    ${TICKS}
