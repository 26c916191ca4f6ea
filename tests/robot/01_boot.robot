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
    Should Match Regexp    ${regs}    R15=fffc01[01][0-9a-f]

The Guest Clock Runs At Host Speed
    [Documentation]    ARM_PLL_CTRL 0x00018008 makes Linux's timer clock
    ...    match QEMU's (with QEMU's own 0x00014008 guest time ran 1.2x fast).
    ${t0}=    Evaluate    time.time()    modules=time
    Execute Shell Command    sleep 2
    ${t1}=    Evaluate    time.time()    modules=time
    ${took}=    Evaluate    ${t1} - ${t0}
    Should Be True    1.5 <= ${took} <= 4    sleep 2 took ${took} s on the host

Linux Stays Healthy
    ${out}=    Execute Shell Command    cat /proc/loadavg; echo alive
    Should Contain    ${out}    alive
