# SPDX-License-Identifier: GPL-2.0-only
# Out-of-tree build of one of servoamp's kernel modules against the
# servoamp kernel; included by linux/<module>/Makefile, which sets
#   NAME   the build folder's name (build/linux/NAME/<kernel key>)
#   SRCS   the Kbuild and the sources, copied to $(BUILD)
#   HDRS   headers of the repository's include/, copied to $(BUILD)/include
#   CHECK  the files checkpatch.pl checks
#
#   make                 # build into $(BUILD) (default:
#                        # build/linux/NAME/<kernel key>, one per kernel)
#   make checkpatch      # the kernel's checkpatch.pl on the sources
#   make clean
#
# KDIR is the kernel's O= build tree (linux/kernel/build.sh prepares it and
# links it as build/kernel-rt, the board's kernel; build/kernel for
# --variant vanilla; linux/kernel/build-zynqmp.sh, build/kernel-zynqmp, the
# ZynqMP's arm64 kernel). The kernel's architecture comes from its info
# file (arch=, arm when absent), the compiler from that architecture's row
# of scripts/mk/guest-arch.mk. The sources are copied to $(BUILD) so that
# no build output lands in the source tree.
REPO    ?= $(abspath $(CURDIR)/../..)
KDIR    ?= $(REPO)/build/kernel-rt/obj
KINFO   := $(KDIR)/../info
BUILD   ?= $(REPO)/build/linux/$(NAME)/$(shell sed -n 's/^key=//p' $(KINFO))
KSRC    ?= $(shell sed -n 's/^src=//p' $(KINFO))
KARCH   := $(or $(shell sed -n 's/^arch=//p' $(KINFO)),arm)
GUEST_ARCH = $(call guest_arch_of_karch,$(KARCH))
include $(REPO)/scripts/mk/guest-arch.mk
CROSS_COMPILE ?= $(GUEST_CROSS_$(GUEST_ARCH))

all: $(addprefix $(BUILD)/,$(SRCS)) $(addprefix $(BUILD)/include/,$(HDRS))
	$(MAKE) -C $(KDIR) M=$(BUILD) ARCH=$(KARCH) CROSS_COMPILE=$(CROSS_COMPILE) modules

$(BUILD)/%: % | $(BUILD)
	cp $< $@

$(BUILD)/include/%: $(REPO)/include/%
	mkdir -p $(dir $@)
	cp $< $@

$(BUILD):
	mkdir -p $@

checkpatch:
	for f in $(CHECK); do $(KSRC)/scripts/checkpatch.pl --no-tree --strict -f $$f || exit 1; done

clean:
	rm -rf $(BUILD)

.PHONY: all checkpatch clean
