*** Settings ***
Documentation     Every bad R5 image (tests/zynqmp/fixtures/gen_bad_r5_images.py)
...               is refused by Linux's remoteproc core under the upstream
...               xlnx_r5_remoteproc with the core's reason in the kernel log;
...               the state stays offline, R5 0 stays held, Linux stays
...               healthy, and a good image starts afterwards. A malformed
...               resource table is not a refusal upstream: the core logs
...               why and the driver starts the image without the table.
...               One QEMU boot.
...               What the upstream path does not refuse (another machine's
...               image, section names outside the name table, a trace
...               buffer outside every carveout) is listed in
...               docs/boot-flow-zynqmp.md.
Resource          ../resources/zynqmp.resource
Library           OperatingSystem
Library           String
Suite Setup       Boot Board To Shell
Suite Teardown    Quit Emulation
Test Template     Image Is Refused

*** Test Cases ***                 IMAGE                              REASON
Not An ELF File                    bad-r5-not-elf.elf                 Image is corrupted (bad magic)
Unknown ELF Class                  bad-r5-unknown-class.elf           Unsupported class: 3
Big-Endian Image                   bad-r5-big-endian.elf              Unsupported firmware endianness
Truncated Header                   bad-r5-truncated-header.elf        Image is too small
No Program Headers                 bad-r5-no-program-headers.elf      No loadable segments
Truncated Segment                  bad-r5-truncated-segment.elf       truncated fw: need
File Size Over Memory Size         bad-r5-filesz-over-memsz.elf       bad phdr filesz
Segment Where The R5 Has No Memory    bad-r5-outside.elf              bad phdr da 0x70000000
Segment Crossing The ATCM End      bad-r5-crosses-atcm-end.elf        bad phdr da 0xff00
Trace Entry Reserved Bytes         bad-r5-trace-reserved.elf          trace rsc has non zero reserved bytes
Missing Firmware File              no-such-firmware.elf               request_firmware failed

Resource Table Version 2 Is Dropped
    [Documentation]    The core rejects the table and says why; the upstream
    ...    driver then starts the image as one without a table.
    [Template]    Resource Table Is Dropped
    bad-r5-rsc-version.elf    unsupported fw ver: 2

Resource Table Reserved Bytes Are Dropped
    [Template]    Resource Table Is Dropped
    bad-r5-rsc-reserved.elf    non zero reserved bytes

Resource Entries Past The Table Are Dropped
    [Template]    Resource Table Is Dropped
    bad-r5-rsc-past-table.elf    resource table incomplete

A Good Image Starts After The Bad Ones
    [Template]    NONE
    Clear Terminal Tester Report    ${SERVO_UART}
    Start Firmware    r5-fw-rsc.elf
    Wait For Line On Uart    servoamp r5-fw rsc: running    testerId=${SERVO_UART}
    Stop Firmware

The Bad Images Table Matches The Generator
    [Template]    NONE
    ${tsv}=    Get File    ${CURDIR}/../../../build/tests/fixtures/zynqmp_qemu/bad-r5-images.tsv
    ${lines}=    Get Line Count    ${tsv}
    Should Be Equal As Integers    ${lines}    13
    ${dropped}=    Get Lines Containing String    ${tsv}    \ttable-dropped\t
    ${n}=    Get Line Count    ${dropped}
    Should Be Equal As Integers    ${n}    3

*** Keywords ***
Image Is Refused
    [Arguments]    ${image}    ${reason}
    Execute Shell Command    dmesg -c > /dev/null
    Start Should Be Refused    ${image}
    ${log}=    Execute Shell Command    dmesg
    Should Contain    ${log}    ${reason}
    R5 Should Be Held    ${R5_0}
    ${out}=    Execute Shell Command    echo healthy
    Should Be Equal    ${out}    healthy

Resource Table Is Dropped
    [Arguments]    ${image}    ${reason}
    Execute Shell Command    dmesg -c > /dev/null
    Clear Terminal Tester Report    ${SERVO_UART}
    Start Firmware    ${image}
    ${log}=    Execute Shell Command    dmesg
    Should Contain    ${log}    ${reason}
    Should Contain    ${log}    no resource table found
    Execute Shell Command    test ! -e ${TRACE0}
    Wait For Line On Uart    servoamp r5-fw rsc: running    testerId=${SERVO_UART}
    Stop Firmware
