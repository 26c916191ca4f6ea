*** Settings ***
Documentation     Every bad firmware image (tests/robot/fixtures/
...               gen_bad_images.py) is refused with a reason in the kernel
...               log, the state stays offline, Linux stays healthy, and a
...               good image starts afterwards. One QEMU boot for the suite.
...               The remoteproc core's rproc_elf_sanity_check() runs first
...               (its own wording for a bad magic or a short file), then the
...               driver's checks: program and section headers, section
...               names bounded by the name table, load segments inside the
...               carveout and not overlapping, resource table and trace
...               buffers inside the carveout (32-bit overflow-safe), only
...               the resource entry types the board uses (trace, carveout
...               at fixed addresses: no devmem, vdev, vendor or unknown).
Resource          resources/servoamp.resource
Library           OperatingSystem
Suite Setup       Boot Board To Shell
Suite Teardown    Quit Emulation
Test Template     Image Is Refused

*** Test Cases ***                 IMAGE                           REASON
Not An ELF File                    bad-not-elf.elf                 Image is corrupted (bad magic)
Wrong ELF Class                    bad-wrong-class.elf             refused by the remoteproc core's ELF check
Wrong Machine                      bad-wrong-machine.elf           wrong machine 183, not EM_ARM
Truncated Header                   bad-truncated-header.elf        Image is too small
Truncated Segment                  bad-truncated-segment.elf       truncated: segment 0
Segment Outside The Carveout       bad-outside-carveout.elf        is outside the carveout
Segment Crossing The Carveout End  bad-crosses-carveout-end.elf    is outside the carveout
Segment In The OCM Mailbox         bad-ocm-mailbox.elf             overlaps OCM (amp_lib mailbox)
Segment Over The Boot Stub         bad-ocm-boot-stub.elf           overlaps OCM (boot stub and park loop)
Entry Point Outside                bad-entry-outside.elf           entry point 0x100000 is not inside
Section Name Far Outside The Name Table
    [Documentation]    The old driver let the core's find_table() strcmp()
    ...    at name table + 0x7fff0000 (an oops).
    bad-section-name-outside.elf    section 1: name offset 0x7fff0000 is outside the section name table
Section Name Running Past The Name Table
    bad-section-name-unterminated.elf    is not NUL-terminated inside the section name table
Section Name Table Outside The File
    bad-name-table-outside.elf    section name table [0x7ff00000-0x7ff00026) is outside the file
Overlapping Load Segments
    bad-overlapping-segments.elf    segments 0 [0x1f000000-0x1f001808) and 1 [0x1f000800-0x1f000900) overlap
Misaligned Program Header Table
    [Documentation]    Found by tests/fuzz/fuzz_rproc_check: the core and the
    ...    driver read the header tables in place as u32 structures.
    bad-misaligned-program-headers.elf    header tables at misaligned file offsets (program 0x36
No Section Headers But A Name Table Index
    [Documentation]    Found by tests/fuzz/fuzz_rproc_check: the core's
    ...    find_table() reads section header e_shstrndx even when e_shnum is
    ...    0 (2.6 MB past the table here); the old driver accepted the image.
    bad-no-sections-name-index.elf    no section headers, but section name table index 65535
Trace Buffer Length Wrapping 32 Bits
    [Documentation]    (da - carveout) + len wraps to 0 in the core's
    ...    32-bit rproc_da_to_va(): the old driver started this image.
    bad-trace-len-wraps.elf    trace buffer 'test-fw trace' [0x1f002008 +0xffffdff8) is not inside the carveout
Trace Buffer Outside The Carveout
    bad-trace-outside.elf    trace buffer 'test-fw trace' [0xffff0000 +0x400) is not inside the carveout
Trace Buffer Crossing The Carveout End
    bad-trace-crosses-carveout-end.elf    trace buffer 'test-fw trace' [0x1fffff00 +0x1000) is not inside the carveout
Resource Table Outside The Carveout
    bad-rsc-table-outside.elf    resource table [0x1e000000-0x1e000044) is outside the carveout
Carveout Entry At Any Device Address
    [Documentation]    Issue 20, item 6: the core would allocate Linux memory
    ...    anywhere for it; the old driver let it through unchecked.
    bad-rsc-carveout-da-any.elf    resource entry 1 (type 0) refused: carveout 'test-fw heap' with da FW_RSC_ADDR_ANY
Carveout Entry At Any Physical Address
    bad-rsc-carveout-pa-any.elf    resource entry 1 (type 0) refused: carveout 'test-fw heap' with pa FW_RSC_ADDR_ANY
Device Memory Entry
    bad-rsc-devmem.elf    resource entry 1 (type 1) refused: RSC_DEVMEM maps device memory
Virtio Device Entry
    bad-rsc-vdev.elf    resource entry 1 (type 3) refused: RSC_VDEV is a virtio device
Vendor Resource Entry
    bad-rsc-vendor.elf    resource entry 1 (type 128) refused: vendor-specific
Unknown Resource Type
    bad-rsc-unknown-type.elf    resource entry 1 (type 4) refused: unknown to the remoteproc core
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
    Should Be Equal As Integers    ${lines}    26

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
