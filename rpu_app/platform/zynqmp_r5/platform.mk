# SPDX-License-Identifier: MIT
# rpu_app's platform for the ZynqMP's Cortex-R5F (RPU, split mode), included
# by rpu_app/Makefile when the servo devicetree's CPU is an arm,cortex-r5f:
#   PMSAv7 MPU (mpu.c), the core's PMU cycle counter as time base
#   (pmccntr.c), no idle wake and no park (idle_timer.c: Linux's upstream
#   R5 driver powers the core down to stop it), vectors linked at 0x0 in
#   the ATCM (servo.ld; no VBAR), the RPU's own GIC.
PLAT_ARCHFLAGS := -mcpu=cortex-r5 -marm -mfpu=vfpv3-d16 -mfloat-abi=hard
PLAT_C_SRCS := mpu.c pmccntr.c idle_timer.c
PLAT_S_SRCS :=
PLAT_LDS := $(PLATDIR)/servo.ld
PLAT_EXTRA :=
