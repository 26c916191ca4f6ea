# The guest architectures of servoamp's Linux side, one row each: the
# architecture's Debian name (as linux/initramfs/build.sh --arch and
# python/servoamp/images.py DEBIAN_ARCH name it), the kernel's name for it,
# the cross compiler's prefix and servod's code-generation flags. A board
# picks its row through board.yaml's linux.arch (the kernel's name).
# Included by linux/servod/Makefile, motion/Makefile,
# linux/telemetry/Makefile and linux/kmod.mk.
#
#   armhf  the Zynq-7000's Cortex-A9 (zynq7000_qemu)
#   arm64  the ZynqMP's Cortex-A53 (zynqmp_qemu)
GUEST_ARCHES := armhf arm64

GUEST_KARCH_armhf  := arm
GUEST_CROSS_armhf  := arm-linux-gnueabihf-
GUEST_CFLAGS_armhf := -march=armv7-a -mfpu=vfpv3-d16 -mfloat-abi=hard

GUEST_KARCH_arm64  := arm64
GUEST_CROSS_arm64  := aarch64-linux-gnu-
GUEST_CFLAGS_arm64 := -mcpu=cortex-a53

# the row of a kernel architecture: $(call guest_arch_of_karch,arm64) = arm64
guest_arch_of_karch = $(firstword $(foreach a,$(GUEST_ARCHES),$(if $(filter $(1),$(GUEST_KARCH_$(a))),$(a))))

# the architecture of this build (make GUEST_ARCH=arm64); the includer may
# set it first (kmod.mk: from the kernel's)
GUEST_ARCH ?= armhf
ifeq ($(filter $(GUEST_ARCH),$(GUEST_ARCHES)),)
  $(error GUEST_ARCH=$(GUEST_ARCH): expected one of $(GUEST_ARCHES) (scripts/mk/guest-arch.mk))
endif
