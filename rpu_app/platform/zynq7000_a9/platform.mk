# SPDX-License-Identifier: MIT
# rpu_app's platform for the Zynq-7000's second Cortex-A9 (CPU1), included
# by rpu_app/Makefile when the servo devicetree's CPU is an arm,cortex-a9:
#   MMU (flat section map), the A9 global timer as time base (Linux's),
#   CPU1's private timer as the idle wake, the cooperative stop's park
#   (back to the boot stub's park loop in OCM), VBAR.
PLAT_ARCHFLAGS := -mcpu=cortex-a9 -marm -mfpu=vfpv3-d16 -mfloat-abi=hard
PLAT_C_SRCS := mmu.c gtimer.c idle_timer.c
PLAT_S_SRCS := park.S
PLAT_LDS := $(PLATDIR)/servo.ld
# Test-only OCM stub (park loop + CPU0 hold loop) for QEMU runs without Linux.
STUB := $(BUILD)/qemu-stub.elf
PLAT_EXTRA := $(STUB)

$(STUB): $(APP)/tests/qemu_stub.S $(APP)/tests/qemu_stub.ld $(BUILD)/board_config.h
	$(call say,AS,$@)
	$(Q)$(CC) $(ARCHFLAGS) -I$(BUILD) -nostdlib -nostartfiles -static -L$(BUILD) \
		-T$(APP)/tests/qemu_stub.ld -Wl,--build-id=none $< -o $@

