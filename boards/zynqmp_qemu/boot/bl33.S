// SPDX-License-Identifier: MIT
/*
 * zynqmp_qemu: the BL33 that TF-A's BL31 enters (at EL2, non-secure) in
 * place of U-Boot. TF-A 2.8's zynqmp platform passes no arguments to BL33
 * when it boots without an FSBL hand-off (QEMU has no boot ROM or FSBL: the
 * boot mode reads JTAG and BL31 jumps to PRELOADED_BL33_BASE, this stub),
 * while Linux's arm64 boot protocol wants x0 = the DTB's physical address
 * and x1..x3 = 0. This does only that and branches to the Image. The DTB
 * is the one BL31 has edited in place at XILINX_OF_BOARD_DTB_ADDR (PSCI
 * node, its own reserved memory). Addresses from board.yaml (Makefile).
 *
 * First it does the one thing of the FSBL's (psu_init's) that Linux's R5
 * driver depends on: the RPU's bus (AMBA) and power-gate resets in CRL_APB
 * RST_LPD_TOP released, as on a board whose design uses the RPU. TF-A
 * refuses the RPU mode ioctl while the AMBA reset is held (-EACCES: "failed
 * to set RPU mode"). Each R5's own reset stays with the PMU's wake.
 */
	.text
	.global _start
_start:
	ldr	x6, =RST_LPD_TOP
	ldr	w5, [x6]
	mov	w7, #RPU_RELEASE
	bic	w5, w5, w7
	str	w5, [x6]
	dsb	sy
	ldr	x0, =DTB_ADDR
	mov	x1, xzr
	mov	x2, xzr
	mov	x3, xzr
	ldr	x4, =IMAGE_ADDR
	br	x4
	.ltorg
