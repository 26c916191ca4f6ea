*** Settings ***
Documentation     The emulated zynq7000_qemu board boots Linux on CPU0 to a
...               shell, with CPU1 parked for the servo firmware, the
...               remoteproc driver bound and the carveout kept away from
...               Linux. One QEMU boot for the whole suite.
Resource          resources/servoamp.resource
Suite Setup       Boot Board To Shell
Suite Teardown    Quit Emulation

*** Test Cases ***
Linux Boots To A Shell On UART0
    ${out}=    Execute Shell Command    uname -r
    Should Start With    ${out}    6.1.
    Log    boot times (s): ${BOOT_TIMES}    console=True

Only CPU0 Belongs To Linux
    ${out}=    Execute Shell Command    cat /sys/devices/system/cpu/online
    Should Be Equal    ${out}    0

The Carveout Is Not Linux Memory
    ${out}=    Execute Shell Command    grep -i "system ram" /proc/iomem
    Should Contain    ${out}    00000000-1effffff : System RAM
    Should Not Contain    ${out}    1f000000

UART1 And TTC1 Are Left To The Servo Core
    ${out}=    Execute Shell Command    ls /sys/bus/platform/devices/
    Should Contain    ${out}    e0000000.serial
    Should Not Contain    ${out}    e0001000.serial
    ${status}=    Execute Shell Command    tr -d '\\000' < /sys/firmware/devicetree/base/axi/timer@f8002000/status
    Should Be Equal    ${status}    disabled
    ${timers}=    Execute Shell Command    cat /proc/interrupts
    Should Not Contain    ${timers}    f8002000

The Remoteproc Driver Is Bound And Offline
    ${mods}=    Execute Shell Command    cat /proc/modules
    Should Contain    ${mods}    zynq_servo_rproc
    ${name}=    Execute Shell Command    cat ${RPROC}/name
    Should Be Equal    ${name}    servo-cpu1
    Remoteproc State Should Be    offline
    ${fw}=    Execute Shell Command    cat ${RPROC}/firmware
    Should Be Equal    ${fw}    rpu_app.elf

CPU1 Waits In The Park Loop
    Word Should Be    ${BOOT_REGISTER}    0
    ${cpus}=    Execute Command    info cpus
    Should Contain    ${cpus}    CPU #1
    ${regs}=    Execute Command    info registers    cpu=1
    Should Match Regexp    ${regs}    R15=fffc01[0-9a-f][0-9a-f]

Linux Computes The Timer Clock QEMU Runs
    [Documentation]    ARM_PLL_CTRL 0x00018008 makes Linux compute the
    ...    100 MHz CPU_3x2x clock QEMU runs its A9 timers at (with QEMU's own
    ...    0x00014008 Linux computed 83.3 MHz and guest time ran 1.2x fast).
    # the A9 timers' clock (zynq-7000.dtsi: clkc 4, cpu_3or2x); Linux's
    # integer divisions make it 99999999
    ${rate}=    Execute Shell Command    cat /sys/kernel/debug/clk/cpu_3or2x/clk_rate
    Should Be True    abs(${rate} - 100000000) <= 10    cpu_3or2x is ${rate} Hz

The Guest Clock Follows Its Time Base
    [Documentation]    On the host clock guest time runs at host speed. On
    ...    virtual time (-icount) a guest second is a count of instructions,
    ...    and an idle guest skips ahead to its next timer: it runs faster
    ...    than the host, never slower than a busy host can execute it.
    ${clock}=    Emulation Clock
    ${t0}=    Evaluate    time.time()    modules=time
    ${up}=    Execute Shell Command    cat /proc/uptime; sleep 2; cat /proc/uptime
    ${t1}=    Evaluate    time.time()    modules=time
    ${took}=    Evaluate    ${t1} - ${t0}
    ${guest}=    Evaluate    round(float($up.split()[2]) - float($up.split()[0]), 2)
    Log    ${clock} clock: guest sleep 2 = ${guest} s guest, ${took} s host    console=True
    Should Be True    ${guest} >= 2    sleep 2 took ${guest} s of guest time
    IF    '${clock}' == 'host'
        Should Be True    1.5 <= ${took} <= 4    sleep 2 took ${took} s on the host
    ELSE
        # a timer fires at its exact virtual time: no host delay in between
        Should Be True    ${guest} <= 2.1    sleep 2 took ${guest} s of guest time
    END

Linux Stays Healthy
    ${out}=    Execute Shell Command    cat /proc/loadavg; echo alive
    Should Contain    ${out}    alive
