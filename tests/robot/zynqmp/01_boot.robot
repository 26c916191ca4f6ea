*** Settings ***
Documentation     The emulated zynqmp_qemu board boots as the hardware does:
...               the A53 starts in TF-A's BL31, which enters Linux 6.12
...               (PREEMPT_RT) on one A53; Linux's upstream
...               xlnx_r5_remoteproc binds both R5s (split mode) through
...               TF-A's EEMI services and our QEMU's PMU stand-in, and both
...               stay held in reset until started. One QEMU boot.
Resource          ../resources/zynqmp.resource
Suite Setup       Boot Board To Shell
Suite Teardown    Quit Emulation

*** Test Cases ***
Linux 6.12 PREEMPT_RT Boots To A Shell On UART0
    ${out}=    Execute Shell Command    uname -r; uname -v
    Should Start With    ${out}    6.12.
    Should Contain    ${out}    PREEMPT_RT
    Log    boot times (s): ${BOOT_TIMES}    console=True

TF-A Started Linux At EL2 On One A53
    ${out}=    Execute Shell Command    cat /sys/devices/system/cpu/online
    Should Be Equal    ${out}    0
    ${log}=    Execute Shell Command    dmesg | grep -i -e "CPU: All CPU(s) started at EL2" -e "psci: PSCIv"
    Should Contain    ${log}    EL2
    Should Contain    ${log}    PSCIv

The Upstream R5 Driver Binds Both R5s
    ${names}=    Execute Shell Command    cat /sys/class/remoteproc/remoteproc*/name
    Should Be Equal    ${names}    ffe00000.r5f\nffe90000.r5f
    ${states}=    Execute Shell Command    cat /sys/class/remoteproc/remoteproc*/state
    Should Be Equal    ${states}    offline\noffline
    ${fw}=    Execute Shell Command    cat ${RPROC}/firmware
    ${default}=    Board Value    servo    default_firmware    name
    Should Be Equal    ${fw}    ${default}
    Execute Shell Command    test -e /lib/firmware/${default}

Both R5s Are Held Until Started
    R5 Should Be Held    ${R5_0}
    R5 Should Be Held    ${R5_1}

The Carveouts Are Not Linux Memory
    ${out}=    Execute Shell Command    grep -i "system ram" /proc/iomem
    Should Not Contain    ${out}    3ed00000
    Should Not Contain    ${out}    3ef00000

UART1 Is Left To The R5
    ${out}=    Execute Shell Command    ls /sys/bus/platform/devices/
    Should Contain    ${out}    ff000000.serial
    Should Not Contain    ${out}    ff010000.serial

The Guest Clock Follows Its Time Base
    [Documentation]    On virtual time (-icount, the default) a guest second
    ...    is a count of instructions and a timer fires at its exact time.
    ${clock}=    Emulation Clock
    ${up}=    Execute Shell Command    cat /proc/uptime; sleep 2; cat /proc/uptime
    ${guest}=    Evaluate    round(float($up.split()[2]) - float($up.split()[0]), 2)
    Log    ${clock} clock: guest sleep 2 = ${guest} s guest    console=True
    Should Be True    ${guest} >= 2    sleep 2 took ${guest} s of guest time
    IF    '${clock}' == 'virtual'
        Should Be True    ${guest} <= 2.1    sleep 2 took ${guest} s of guest time
    END
