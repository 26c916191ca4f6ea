*** Settings ***
Documentation     Every bad firmware image (tests/robot/fixtures/
...               gen_bad_images.py) is refused with a reason in the kernel
...               log, the state stays offline, Linux stays healthy, and a
...               good image starts afterwards. One QEMU boot for the suite.
Resource          resources/servoamp.resource
Library           OperatingSystem
Suite Setup       Boot Board To Shell
Suite Teardown    Quit Emulation
Test Template     Image Is Refused

*** Test Cases ***                 IMAGE                           REASON
Not An ELF File                    bad-not-elf.elf                 not an ELF file
Wrong ELF Class                    bad-wrong-class.elf             wrong ELF class 2
Wrong Machine                      bad-wrong-machine.elf           wrong machine 183, not EM_ARM
Truncated Header                   bad-truncated-header.elf        truncated
Truncated Segment                  bad-truncated-segment.elf       truncated: segment 0
Segment Outside The Carveout       bad-outside-carveout.elf        is outside the carveout
Segment Crossing The Carveout End  bad-crosses-carveout-end.elf    is outside the carveout
Segment In The OCM Mailbox         bad-ocm-mailbox.elf             overlaps OCM (amp_lib mailbox)
Segment Over The Boot Stub         bad-ocm-boot-stub.elf           overlaps OCM (boot stub and park loop)
Entry Point Outside                bad-entry-outside.elf           entry point 0x100000 is not inside
Missing Firmware File              no-such-firmware.elf            request_firmware failed

A Good Image Starts After The Bad Ones
    [Template]    NONE
    Start Firmware    test-fw-rsc.elf
    Wait For Line On Uart    servoamp test-fw rsc: running    testerId=${SERVO_UART}
    Stop Firmware

The Bad Images Table Matches The Generator
    [Template]    NONE
    ${tsv}=    Get File    ${CURDIR}/../../build/tests/fixtures/bad-images.tsv
    ${lines}=    Get Line Count    ${tsv}
    Should Be Equal As Integers    ${lines}    10

*** Keywords ***
Image Is Refused
    [Arguments]    ${image}    ${reason}
    Execute Shell Command    dmesg -c > /dev/null
    Start Should Be Refused    ${image}
    ${log}=    Execute Shell Command    dmesg
    Should Contain    ${log}    ${reason}
    Word Should Be    ${BOOT_REGISTER}    0
    ${out}=    Execute Shell Command    echo healthy
    Should Be Equal    ${out}    healthy
