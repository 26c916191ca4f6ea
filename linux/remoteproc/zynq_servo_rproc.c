// SPDX-License-Identifier: GPL-2.0-only
/*
 * Remote processor driver for the servo core of a Zynq-7000: the second
 * Cortex-A9 (CPU1), kept out of Linux with maxcpus=1, running bare-metal
 * servo firmware from a reserved-memory carveout in DDR.
 *
 * Boot protocol (the one of the Zynq-7000 boot ROM, Xilinx XAPP1079):
 * CPU1 waits in a park loop (wfe; read the boot register 0xfffffff0; branch
 * to it when it is not zero). The boot stub of the board keeps this loop at
 * a fixed OCM address so that a firmware can branch back to it.
 *
 * Start: the ELF image is loaded into the carveout, the driver clears the
 * OCM status word, writes "run" to the OCM control word, writes the entry
 * point to the boot register, dsb, sev, and waits (bounded) for the
 * firmware to write 'RUN!' to the status word.
 *
 * Stop (cooperative): the driver zeroes the boot register, writes 'STOP' to
 * the control word, dsb, sev, and waits (bounded) for the firmware to write
 * 'PRKD' to the status word just before it branches back to the park loop.
 * If the firmware does not park in time, CPU1 is reset through the SLCR
 * (A9_CPU_RST_CTRL) when the devicetree gives the SLCR; the boot ROM of a
 * real Zynq-7000 then parks it again on the (zeroed) boot register. QEMU
 * only stores that register (hw/misc/zynq_slcr.c): an emulated CPU1 keeps
 * running.
 *
 * A stop is confirmed only by 'PRKD' in the status word: the firmware's own
 * answer, late or not. Nothing else can tell the driver that CPU1 no longer
 * executes from the carveout (neither the boot ROM nor the board's park loop
 * writes the status word, and reading A9_CPU_RST_CTRL back proves nothing on
 * QEMU). A stop that cannot be confirmed is an error: the core then keeps
 * the state "running", and the driver refuses to load any image (including
 * after a reload of the driver, which finds 'RUN!' still in the status word)
 * until a new park request is answered.
 *
 * Copyright (C) 2026 The servoamp authors
 */

#include <linux/delay.h>
#include <linux/elf.h>
#include <linux/firmware.h>
#include <linux/io.h>
#include <linux/iopoll.h>
#include <linux/kernel.h>
#include <linux/mfd/syscon.h>
#include <linux/module.h>
#include <linux/of.h>
#include <linux/of_address.h>
#include <linux/of_reserved_mem.h>
#include <linux/platform_device.h>
#include <linux/overflow.h>
#include <linux/regmap.h>
#include <linux/remoteproc.h>
#include <linux/rsc_table.h>
#include <linux/string.h>
#include <asm/barrier.h>

#include "remoteproc_internal.h"

/* OCM control word (driver-owned) and status word (firmware-owned) */
#include "servoamp/rproc_words.h"

/* SLCR: CPU1 reset and clock stop, used only when a stop times out */
#define ZSR_SLCR_A9_CPU_RST_CTRL	0x244
#define ZSR_A9_RST1			BIT(1)
#define ZSR_A9_CLKSTOP1			BIT(5)

/* On-chip memory of the Zynq-7000, mapped high (0xfffc0000-0xffffffff) */
#define ZSR_OCM_BASE		0xfffc0000ULL
#define ZSR_OCM_END		0x100000000ULL	/* exclusive */

#define ZSR_DEFAULT_START_TIMEOUT_MS	1000
#define ZSR_DEFAULT_STOP_TIMEOUT_MS	500
#define ZSR_POLL_US			100
/* how long 'PRKD' may still take to appear after an SLCR reset */
#define ZSR_RESET_CONFIRM_MS		50
/* no servo firmware has more PT_LOAD segments (the overlap check is O(n^2)) */
#define ZSR_MAX_LOAD_SEGMENTS		32
#define ZSR_DEFAULT_FIRMWARE		"servoamp-rpu.elf"

/**
 * struct zsr_region - a named physical address range [start, end)
 * @name: what the range is, for error messages
 * @start: first address
 * @end: first address after the range
 */
struct zsr_region {
	const char *name;
	u64 start;
	u64 end;
};

enum {
	ZSR_OCM_STUB,
	ZSR_OCM_MAILBOX,
	ZSR_OCM_CONTROL,
	ZSR_OCM_BOOT_REG,
	ZSR_OCM_NUM,
};

/**
 * struct zynq_servo_rproc - state of one servo core
 * @dev: the platform device
 * @rproc: the remoteproc handle
 * @ctrl: OCM control (offset 0) and status (offset 4) words
 * @boot: the CPU1 boot register (0xfffffff0)
 * @slcr: SLCR regmap for the CPU1 reset, or NULL when not described
 * @carveout: the reserved-memory region the firmware runs from
 * @ocm: OCM ranges the firmware must not load into, with their names
 * @park_addr: address of the CPU1 park loop
 * @start_timeout_ms: bound on the wait for 'RUN!' after a start
 * @stop_timeout_ms: bound on the wait for 'PRKD' after a stop request
 * @cpu1_unconfirmed: a stop could not be confirmed: CPU1 may still execute
 *	a firmware from the carveout, so nothing may be loaded
 */
struct zynq_servo_rproc {
	struct device *dev;
	struct rproc *rproc;
	void __iomem *ctrl;
	void __iomem *boot;
	struct regmap *slcr;
	struct zsr_region carveout;
	struct zsr_region ocm[ZSR_OCM_NUM];
	u32 park_addr;
	u32 start_timeout_ms;
	u32 stop_timeout_ms;
	bool cpu1_unconfirmed;
};

static bool zsr_overlaps(u64 start, u64 end, const struct zsr_region *r)
{
	return start < r->end && r->start < end;
}

/**
 * zsr_ocm_owner() - name the OCM area that a range overlaps
 * @zsr: the servo core
 * @start: first address of the range
 * @end: first address after the range
 *
 * Return: a description of the first driver-known OCM area overlapped by
 * [@start, @end), "on-chip memory" for any other OCM address, or NULL when
 * the range does not touch OCM at all.
 */
static const char *zsr_ocm_owner(struct zynq_servo_rproc *zsr, u64 start,
				 u64 end)
{
	const struct zsr_region ocm = { NULL, ZSR_OCM_BASE, ZSR_OCM_END };
	int i;

	for (i = 0; i < ZSR_OCM_NUM; i++)
		if (zsr->ocm[i].end && zsr_overlaps(start, end, &zsr->ocm[i]))
			return zsr->ocm[i].name;

	return zsr_overlaps(start, end, &ocm) ? "on-chip memory" : NULL;
}

/**
 * zsr_reset_cpu1() - reset CPU1 through the SLCR after a failed stop
 * @zsr: the servo core
 *
 * On a real Zynq-7000, CPU1 leaves reset in the boot ROM, which waits on the
 * (already zeroed) boot register: it is parked again. QEMU only stores
 * A9_CPU_RST_CTRL, so an emulated CPU1 is not affected by this write.
 *
 * Return: 0 when the reset was written, a negative error code when there is
 * no SLCR or the write failed.
 */
static int zsr_reset_cpu1(struct zynq_servo_rproc *zsr)
{
	const u32 mask = ZSR_A9_RST1 | ZSR_A9_CLKSTOP1;
	int ret;

	if (!zsr->slcr)
		return -ENODEV;

	ret = regmap_update_bits(zsr->slcr, ZSR_SLCR_A9_CPU_RST_CTRL, mask,
				 mask);
	if (ret)
		goto err;
	usleep_range(10, 20);
	ret = regmap_update_bits(zsr->slcr, ZSR_SLCR_A9_CPU_RST_CTRL,
				 ZSR_A9_RST1, 0);
	if (ret)
		goto err;
	ret = regmap_update_bits(zsr->slcr, ZSR_SLCR_A9_CPU_RST_CTRL,
				 ZSR_A9_CLKSTOP1, 0);
	if (ret)
		goto err;
	dev_warn(zsr->dev, "CPU1 reset through SLCR A9_CPU_RST_CTRL\n");
	return 0;

err:
	dev_err(zsr->dev, "SLCR write failed: %d\n", ret);
	return ret;
}

static int zsr_wait_parked(struct zynq_servo_rproc *zsr, u32 timeout_ms)
{
	u32 status;

	return readl_poll_timeout(zsr->ctrl + ZSR_STATUS_OFFSET, status,
				  status == ZSR_STATUS_PARKED, ZSR_POLL_US,
				  timeout_ms * USEC_PER_MSEC);
}

/**
 * zsr_park() - ask the firmware to return to the park loop and wait for it
 * @zsr: the servo core
 *
 * Return: 0 when the firmware reported 'PRKD', -ETIMEDOUT otherwise.
 */
static int zsr_park(struct zynq_servo_rproc *zsr)
{
	/* the park loop must find no entry point once the firmware is there */
	writel(0, zsr->boot);
	writel(ZSR_CTRL_STOP, zsr->ctrl + ZSR_CTRL_OFFSET);
	dsb(ishst);
	sev();

	return zsr_wait_parked(zsr, zsr->stop_timeout_ms);
}

/**
 * zsr_halt() - bring CPU1 back to the park loop, or say why it is not known
 * to be there
 * @zsr: the servo core
 *
 * Asks the firmware to park; when it does not answer in time, resets CPU1
 * through the SLCR (when described) and reads the status word again: a
 * firmware that parked late, or a park loop that announces itself, still
 * confirms the stop. Anything else leaves @zsr->cpu1_unconfirmed set, and
 * no image is loaded until a later call confirms the park.
 *
 * Return: 0 when CPU1 is known parked ('PRKD'), -ETIMEDOUT otherwise.
 */
static int zsr_halt(struct zynq_servo_rproc *zsr)
{
	u32 status;

	if (!zsr_park(zsr))
		goto parked;

	status = readl(zsr->ctrl + ZSR_STATUS_OFFSET);
	dev_err(zsr->dev, "firmware did not park within %u ms (status 0x%08x)%s\n",
		zsr->stop_timeout_ms, status,
		zsr->slcr ? ": resetting CPU1" : "");
	if (!zsr_reset_cpu1(zsr) &&
	    !zsr_wait_parked(zsr, ZSR_RESET_CONFIRM_MS))
		goto parked;

	zsr->cpu1_unconfirmed = true;
	status = readl(zsr->ctrl + ZSR_STATUS_OFFSET);
	if (zsr->slcr)
		dev_err(zsr->dev, "CPU1 not confirmed stopped: status 0x%08x, not 'PRKD', %u ms after the SLCR reset (QEMU ignores that reset, and a boot ROM does not write 'PRKD'); the firmware may still run from the carveout: nothing will be loaded until CPU1 parks\n",
			status, ZSR_RESET_CONFIRM_MS);
	else
		dev_err(zsr->dev, "CPU1 not confirmed stopped: status 0x%08x, not 'PRKD', and no SLCR is described to reset CPU1; the firmware may still run from the carveout: nothing will be loaded until CPU1 parks\n",
			status);
	return -ETIMEDOUT;

parked:
	if (zsr->cpu1_unconfirmed)
		dev_info(zsr->dev, "CPU1 parked: images may be loaded again\n");
	zsr->cpu1_unconfirmed = false;
	return 0;
}

/**
 * zsr_may_load() - refuse to load while CPU1 is not known to be parked
 * @zsr: the servo core
 * @name: the image about to be loaded, for the message
 * @retry: ask CPU1 to park again first
 *
 * Return: 0 when CPU1 is known parked, -EBUSY otherwise.
 */
static int zsr_may_load(struct zynq_servo_rproc *zsr, const char *name,
			bool retry)
{
	if (!zsr->cpu1_unconfirmed)
		return 0;
	if (retry) {
		dev_warn(zsr->dev, "%s: a stop of CPU1 was not confirmed: asking it to park again\n",
			 name);
		if (!zsr_halt(zsr))
			return 0;
	}
	dev_err(zsr->dev, "%s: not loaded: CPU1 is not known to be parked or reset and may still run a firmware from the carveout\n",
		name);
	return -EBUSY;
}

/**
 * zsr_check_ehdr() - what the core's rproc_elf_sanity_check() leaves open
 * @zsr: the servo core
 * @name: the image name, for messages
 * @fw: an image that passed rproc_elf_sanity_check()
 *
 * Return: 0 for an ELF32 ARM executable whose program and section header
 * tables lie inside the file, -EINVAL otherwise.
 */
static int zsr_check_ehdr(struct zynq_servo_rproc *zsr, const char *name,
			  const struct firmware *fw)
{
	const struct elf32_hdr *ehdr = (const struct elf32_hdr *)fw->data;
	struct device *dev = zsr->dev;
	u64 off_end;

	if (ehdr->e_ident[EI_CLASS] != ELFCLASS32) {
		dev_err(dev, "%s: wrong ELF class %u, the Cortex-A9 servo core needs ELF32\n",
			name, ehdr->e_ident[EI_CLASS]);
		return -EINVAL;
	}
	if (ehdr->e_machine != EM_ARM) {
		dev_err(dev, "%s: wrong machine %u, not EM_ARM (%u)\n",
			name, ehdr->e_machine, EM_ARM);
		return -EINVAL;
	}
	if (ehdr->e_type != ET_EXEC) {
		dev_err(dev, "%s: ELF type %u is not an executable\n",
			name, ehdr->e_type);
		return -EINVAL;
	}
	if (ehdr->e_phentsize != sizeof(struct elf32_phdr)) {
		dev_err(dev, "%s: program header entry size %u is not %zu\n",
			name, ehdr->e_phentsize, sizeof(struct elf32_phdr));
		return -EINVAL;
	}
	off_end = (u64)ehdr->e_phoff +
		  (u64)ehdr->e_phnum * sizeof(struct elf32_phdr);
	if (off_end > fw->size) {
		dev_err(dev, "%s: truncated: program headers end at %llu, file has %zu bytes\n",
			name, off_end, fw->size);
		return -EINVAL;
	}
	if (!ehdr->e_shnum)
		return 0;
	if (ehdr->e_shentsize != sizeof(struct elf32_shdr) ||
	    ehdr->e_shstrndx >= ehdr->e_shnum) {
		dev_err(dev, "%s: malformed section header table\n", name);
		return -EINVAL;
	}
	off_end = (u64)ehdr->e_shoff +
		  (u64)ehdr->e_shnum * sizeof(struct elf32_shdr);
	if (off_end > fw->size) {
		dev_err(dev, "%s: truncated: section headers end at %llu, file has %zu bytes\n",
			name, off_end, fw->size);
		return -EINVAL;
	}

	return 0;
}

/**
 * zsr_check_segments() - every PT_LOAD segment inside the file and the
 * carveout, never in OCM, no two overlapping, the entry point in one
 * @zsr: the servo core
 * @name: the image name, for messages
 * @fw: an image that passed zsr_check_ehdr()
 *
 * rproc_elf_load_segments() loads each segment at its physical address, in
 * table order: overlapping segments would overwrite each other.
 *
 * Return: 0 if the segments can be loaded, -EINVAL otherwise.
 */
static int zsr_check_segments(struct zynq_servo_rproc *zsr, const char *name,
			      const struct firmware *fw)
{
	const struct elf32_hdr *ehdr = (const struct elf32_hdr *)fw->data;
	const struct elf32_phdr *phdr, *prev;
	struct device *dev = zsr->dev;
	u64 start, end, off_end;
	unsigned int loads = 0;
	bool entry_ok = false;
	const char *owner;
	int i, j;

	phdr = (const struct elf32_phdr *)(fw->data + ehdr->e_phoff);
	for (i = 0; i < ehdr->e_phnum; i++) {
		if (phdr[i].p_type != PT_LOAD || !phdr[i].p_memsz)
			continue;
		if (++loads > ZSR_MAX_LOAD_SEGMENTS) {
			dev_err(dev, "%s: more than %u loadable segments\n",
				name, ZSR_MAX_LOAD_SEGMENTS);
			return -EINVAL;
		}
		if (phdr[i].p_filesz > phdr[i].p_memsz) {
			dev_err(dev, "%s: segment %d: file size 0x%x larger than memory size 0x%x\n",
				name, i, phdr[i].p_filesz, phdr[i].p_memsz);
			return -EINVAL;
		}
		off_end = (u64)phdr[i].p_offset + phdr[i].p_filesz;
		if (off_end > fw->size) {
			dev_err(dev, "%s: truncated: segment %d needs bytes up to %llu, file has %zu\n",
				name, i, off_end, fw->size);
			return -EINVAL;
		}
		/* u64: a 32-bit address plus a 32-bit size cannot wrap */
		start = phdr[i].p_paddr;
		end = start + phdr[i].p_memsz;
		owner = zsr_ocm_owner(zsr, start, end);
		if (owner) {
			dev_err(dev, "%s: segment %d [0x%llx-0x%llx) overlaps OCM (%s), which the firmware does not own\n",
				name, i, start, end, owner);
			return -EINVAL;
		}
		if (start < zsr->carveout.start || end > zsr->carveout.end) {
			dev_err(dev, "%s: segment %d [0x%llx-0x%llx) is outside the carveout [0x%llx-0x%llx)\n",
				name, i, start, end, zsr->carveout.start,
				zsr->carveout.end);
			return -EINVAL;
		}
		for (j = 0; j < i; j++) {
			prev = &phdr[j];
			if (prev->p_type != PT_LOAD || !prev->p_memsz ||
			    start >= (u64)prev->p_paddr + prev->p_memsz ||
			    prev->p_paddr >= end)
				continue;
			dev_err(dev, "%s: segments %d [0x%x-0x%llx) and %d [0x%llx-0x%llx) overlap\n",
				name, j, prev->p_paddr,
				(u64)prev->p_paddr + prev->p_memsz, i, start,
				end);
			return -EINVAL;
		}
		if (ehdr->e_entry >= start && ehdr->e_entry < end)
			entry_ok = true;
	}

	if (!entry_ok) {
		dev_err(dev, "%s: entry point 0x%x is not inside a loadable segment in the carveout\n",
			name, ehdr->e_entry);
		return -EINVAL;
	}

	return 0;
}

/**
 * zsr_check_section_names() - every section name inside the name table
 * @zsr: the servo core
 * @name: the image name, for messages
 * @fw: an image that passed zsr_check_ehdr()
 *
 * The core's find_table() strcmp()s the name of every section, at the name
 * table's file offset plus sh_name, with no bound: the name table must lie
 * inside the file and every name must start, and end with a NUL, inside it.
 *
 * Return: 0 if all names are bounded, -EINVAL otherwise.
 */
static int zsr_check_section_names(struct zynq_servo_rproc *zsr,
				   const char *name, const struct firmware *fw)
{
	const struct elf32_hdr *ehdr = (const struct elf32_hdr *)fw->data;
	const struct elf32_shdr *shdr, *strtab;
	struct device *dev = zsr->dev;
	const char *names;
	u64 end;
	u32 off;
	int i;

	if (!ehdr->e_shnum)
		return 0;

	shdr = (const struct elf32_shdr *)(fw->data + ehdr->e_shoff);
	strtab = &shdr[ehdr->e_shstrndx];
	end = (u64)strtab->sh_offset + strtab->sh_size;
	if (end > fw->size) {
		dev_err(dev, "%s: section name table [0x%x-0x%llx) is outside the file (%zu bytes)\n",
			name, strtab->sh_offset, end, fw->size);
		return -EINVAL;
	}
	names = (const char *)fw->data + strtab->sh_offset;

	for (i = 0; i < ehdr->e_shnum; i++) {
		off = shdr[i].sh_name;
		if (off >= strtab->sh_size) {
			dev_err(dev, "%s: section %d: name offset 0x%x is outside the section name table (%u bytes)\n",
				name, i, off, strtab->sh_size);
			return -EINVAL;
		}
		if (!memchr(names + off, '\0', strtab->sh_size - off)) {
			dev_err(dev, "%s: section %d: name at offset 0x%x is not NUL-terminated inside the section name table\n",
				name, i, off);
			return -EINVAL;
		}
	}

	return 0;
}

/**
 * zsr_rsc_section() - the section the core takes as the resource table
 * @fw: an image that passed zsr_check_section_names()
 *
 * Return: the first section named ".resource_table", as find_table() picks
 * it, or NULL.
 */
static const struct elf32_shdr *zsr_rsc_section(const struct firmware *fw)
{
	const struct elf32_hdr *ehdr = (const struct elf32_hdr *)fw->data;
	const struct elf32_shdr *shdr;
	const char *names;
	int i;

	if (!ehdr->e_shnum)
		return NULL;

	shdr = (const struct elf32_shdr *)(fw->data + ehdr->e_shoff);
	names = (const char *)fw->data + shdr[ehdr->e_shstrndx].sh_offset;
	for (i = 0; i < ehdr->e_shnum; i++)
		if (!strcmp(names + shdr[i].sh_name, ".resource_table"))
			return &shdr[i];

	return NULL;
}

/**
 * zsr_in_carveout() - whether [@da, @da + @len) lies inside the carveout
 * @zsr: the servo core
 * @da: first device address
 * @len: length in bytes
 *
 * In u64, so that a @len near 4 GiB cannot wrap the sum (the core's
 * rproc_da_to_va() adds them in 32 bits).
 */
static bool zsr_in_carveout(const struct zynq_servo_rproc *zsr, u32 da,
			    u32 len)
{
	return da >= zsr->carveout.start &&
	       (u64)da + len <= zsr->carveout.end;
}

struct zsr_rsc_check {
	struct zynq_servo_rproc *zsr;
	const char *name;
};

/* rsc_table_for_each_entry() callback: entries checked against the carveout */
static int zsr_check_rsc_entry(u32 type, void *rsc, int offset, int avail,
			       void *data)
{
	const struct zsr_rsc_check *c = data;
	struct zynq_servo_rproc *zsr = c->zsr;
	const struct fw_rsc_carveout *mem = rsc;
	const struct fw_rsc_trace *trace = rsc;

	switch (type) {
	case RSC_TRACE:
		if (avail < (int)sizeof(*trace)) {
			dev_err(zsr->dev, "%s: trace entry at offset %d is truncated\n",
				c->name, offset);
			return -EINVAL;
		}
		if (!zsr_in_carveout(zsr, trace->da, trace->len)) {
			dev_err(zsr->dev, "%s: trace buffer '%.32s' [0x%x +0x%x) is not inside the carveout [0x%llx-0x%llx)\n",
				c->name, (const char *)trace->name, trace->da,
				trace->len, zsr->carveout.start,
				zsr->carveout.end);
			return -EINVAL;
		}
		break;
	case RSC_CARVEOUT:
		if (avail < (int)sizeof(*mem)) {
			dev_err(zsr->dev, "%s: carveout entry at offset %d is truncated\n",
				c->name, offset);
			return -EINVAL;
		}
		if (mem->da != (u32)FW_RSC_ADDR_ANY &&
		    !zsr_in_carveout(zsr, mem->da, mem->len)) {
			dev_err(zsr->dev, "%s: carveout entry '%.32s' [0x%x +0x%x) is not inside the carveout [0x%llx-0x%llx)\n",
				c->name, (const char *)mem->name, mem->da,
				mem->len, zsr->carveout.start,
				zsr->carveout.end);
			return -EINVAL;
		}
		break;
	}

	return 0;
}

/**
 * zsr_check_rsc_table() - the resource table and its entries fit the board
 * @zsr: the servo core
 * @name: the image name, for messages
 * @fw: the image
 * @sh: its .resource_table section
 *
 * The core checks the table's header when it reads it; the driver checks
 * first that it can walk the table, then that the table is loaded into the
 * carveout (the core copies it there before the start) and that every
 * trace buffer and carveout entry lies inside the carveout.
 *
 * Return: 0 if the table fits, -EINVAL otherwise.
 */
static int zsr_check_rsc_table(struct zynq_servo_rproc *zsr, const char *name,
			       const struct firmware *fw,
			       const struct elf32_shdr *sh)
{
	struct zsr_rsc_check c = { zsr, name };
	struct device *dev = zsr->dev;
	struct resource_table *table;
	u64 end;

	end = (u64)sh->sh_offset + sh->sh_size;
	if (end > fw->size) {
		dev_err(dev, "%s: resource table [0x%x-0x%llx) is outside the file (%zu bytes)\n",
			name, sh->sh_offset, end, fw->size);
		return -EINVAL;
	}
	if (sh->sh_size < sizeof(*table)) {
		dev_err(dev, "%s: resource table of %u bytes has no header\n",
			name, sh->sh_size);
		return -EINVAL;
	}
	/* rsc_table_for_each_entry() only reads through this pointer */
	table = (struct resource_table *)(fw->data + sh->sh_offset);
	if (struct_size(table, offset, table->num) > sh->sh_size) {
		dev_err(dev, "%s: resource table lists %u entries, more than its %u bytes hold\n",
			name, table->num, sh->sh_size);
		return -EINVAL;
	}
	if (!zsr_in_carveout(zsr, sh->sh_addr, sh->sh_size)) {
		dev_err(dev, "%s: resource table [0x%x-0x%llx) is outside the carveout [0x%llx-0x%llx)\n",
			name, sh->sh_addr, (u64)sh->sh_addr + sh->sh_size,
			zsr->carveout.start, zsr->carveout.end);
		return -EINVAL;
	}

	return rsc_table_for_each_entry(table, sh->sh_size, dev,
					zsr_check_rsc_entry, &c);
}

/**
 * zsr_sanity_check() - refuse any image the servo core cannot run
 * @rproc: the remote processor handle
 * @fw: the firmware image
 *
 * Nothing is loaded while a stop of CPU1 is unconfirmed. Then the core's
 * rproc_elf_sanity_check() (magic, class, endianness, a first look at the
 * header tables), then what is specific to this board: ELF32 ARM
 * executable, header tables inside the file, section names bounded by the
 * name table, PT_LOAD segments inside the file and the carveout, never in
 * OCM, not overlapping, the entry point in one of them, and the resource
 * table (if any) and its entries inside the carveout. Every refusal logs
 * the reason.
 *
 * Return: 0 if the image can be loaded, a negative error code otherwise.
 */
static int zsr_sanity_check(struct rproc *rproc, const struct firmware *fw)
{
	struct zynq_servo_rproc *zsr = rproc->priv;
	const char *name = rproc->firmware;
	const struct elf32_shdr *rsc;
	int ret;

	ret = zsr_may_load(zsr, name, true);
	if (ret)
		return ret;

	ret = rproc_elf_sanity_check(rproc, fw);
	if (ret) {
		dev_err(zsr->dev, "%s: refused by the remoteproc core's ELF check\n",
			name);
		return ret;
	}

	ret = zsr_check_ehdr(zsr, name, fw);
	if (ret)
		return ret;
	ret = zsr_check_segments(zsr, name, fw);
	if (ret)
		return ret;
	ret = zsr_check_section_names(zsr, name, fw);
	if (ret)
		return ret;

	rsc = zsr_rsc_section(fw);
	if (rsc)
		return zsr_check_rsc_table(zsr, name, fw, rsc);

	return 0;
}

/* the core loads through here: never while CPU1 may still run a firmware */
static int zsr_load(struct rproc *rproc, const struct firmware *fw)
{
	struct zynq_servo_rproc *zsr = rproc->priv;
	int ret;

	ret = zsr_may_load(zsr, rproc->firmware, false);
	if (ret)
		return ret;

	return rproc_elf_load_segments(rproc, fw);
}

static int zsr_mem_alloc(struct rproc *rproc, struct rproc_mem_entry *mem)
{
	void __iomem *va;

	va = ioremap_wc(mem->dma, mem->len);
	if (!va) {
		dev_err(&rproc->dev, "cannot map carveout %pad (%zu bytes)\n",
			&mem->dma, mem->len);
		return -ENOMEM;
	}

	mem->va = (__force void *)va;
	mem->is_iomem = true;

	return 0;
}

static int zsr_mem_release(struct rproc *rproc, struct rproc_mem_entry *mem)
{
	iounmap((__force void __iomem *)mem->va);

	return 0;
}

/**
 * zsr_parse_fw() - read the optional resource table, register the carveout
 * @rproc: the remote processor handle
 * @fw: a firmware image that passed zsr_sanity_check()
 *
 * A firmware without a .resource_table section is valid: it simply has no
 * trace buffer and no virtio devices. A .resource_table that is present but
 * malformed is refused. The carveout is registered last, so that a refusal
 * leaves nothing behind (the core does not clean up after parse_fw errors).
 *
 * Return: 0 on success, a negative error code otherwise.
 */
static int zsr_parse_fw(struct rproc *rproc, const struct firmware *fw)
{
	struct zynq_servo_rproc *zsr = rproc->priv;
	struct rproc_mem_entry *mem;
	int ret;

	if (zsr_rsc_section(fw)) {
		ret = rproc_elf_load_rsc_table(rproc, fw);
		if (ret) {
			dev_err(zsr->dev, "%s: invalid resource table\n",
				rproc->firmware);
			return ret;
		}
	} else {
		dev_info(zsr->dev, "%s has no resource table\n",
			 rproc->firmware);
	}

	mem = rproc_mem_entry_init(zsr->dev, NULL,
				   (dma_addr_t)zsr->carveout.start,
				   zsr->carveout.end - zsr->carveout.start,
				   (u32)zsr->carveout.start, zsr_mem_alloc,
				   zsr_mem_release, "servo-carveout");
	if (!mem)
		return -ENOMEM;
	rproc_add_carveout(rproc, mem);

	return 0;
}

/**
 * zsr_stop() - cooperative stop of the servo firmware
 * @rproc: the remote processor handle
 *
 * See the comment at the top of this file and zsr_halt(). A stop that cannot
 * be confirmed fails: the core keeps the state "running", a new "stop" asks
 * again, and nothing is loaded meanwhile.
 *
 * Return: 0 when CPU1 is known parked, -ETIMEDOUT otherwise.
 */
static int zsr_stop(struct rproc *rproc)
{
	return zsr_halt(rproc->priv);
}

/**
 * zsr_start() - release CPU1 from the park loop into the loaded firmware
 * @rproc: the remote processor handle
 *
 * Return: 0 when the firmware reported 'RUN!' in time, -ETIMEDOUT
 * otherwise (CPU1 is then asked to park, or reset; see zsr_halt()).
 */
static int zsr_start(struct rproc *rproc)
{
	struct zynq_servo_rproc *zsr = rproc->priv;
	u32 entry = (u32)rproc->bootaddr;
	ktime_t t0;
	u32 status;
	int ret;

	/*
	 * Forget what a previous run left in OCM, so that a stale 'RUN!' is
	 * never taken for this firmware's answer. writel() orders the image
	 * writes to the carveout (write-combined mapping) before these.
	 */
	writel(0, zsr->ctrl + ZSR_STATUS_OFFSET);
	writel(ZSR_CTRL_RUN, zsr->ctrl + ZSR_CTRL_OFFSET);
	writel(entry, zsr->boot);
	dsb(ishst);
	sev();
	t0 = ktime_get();

	ret = readl_poll_timeout(zsr->ctrl + ZSR_STATUS_OFFSET, status,
				 status == ZSR_STATUS_RUNNING, ZSR_POLL_US,
				 zsr->start_timeout_ms * USEC_PER_MSEC);
	if (ret) {
		dev_err(zsr->dev, "firmware at 0x%08x did not report RUN! within %u ms (status 0x%08x)\n",
			entry, zsr->start_timeout_ms, status);
		zsr_halt(zsr);
		return ret;
	}

	dev_info(zsr->dev, "CPU1 running firmware at 0x%08x (RUN! after %lld us)\n",
		 entry, ktime_us_delta(ktime_get(), t0));
	return 0;
}

static const struct rproc_ops zsr_ops = {
	.start			= zsr_start,
	.stop			= zsr_stop,
	.parse_fw		= zsr_parse_fw,
	.sanity_check		= zsr_sanity_check,
	.get_boot_addr		= rproc_elf_get_boot_addr,
	.load			= zsr_load,
	.find_loaded_rsc_table	= rproc_elf_find_loaded_rsc_table,
};

/**
 * zsr_of_region() - read the first reg entry of a phandle's node
 * @zsr: the servo core
 * @prop: the phandle property
 * @r: filled with the range
 * @required: whether a missing property is an error
 *
 * Return: 0 on success or when an optional property is absent, a negative
 * error code otherwise.
 */
static int zsr_of_region(struct zynq_servo_rproc *zsr, const char *prop,
			 struct zsr_region *r, bool required)
{
	struct device_node *np;
	struct resource res;
	int ret;

	np = of_parse_phandle(zsr->dev->of_node, prop, 0);
	if (!np) {
		if (!required)
			return 0;
		dev_err(zsr->dev, "missing %s\n", prop);
		return -EINVAL;
	}

	ret = of_address_to_resource(np, 0, &res);
	if (ret) {
		dev_err(zsr->dev, "%s: %pOF has no usable reg\n", prop, np);
		goto out;
	}
	r->start = res.start;
	r->end = (u64)res.end + 1;
out:
	of_node_put(np);
	return ret;
}

/**
 * zsr_of_init() - read the devicetree node
 * @zsr: the servo core
 * @pdev: the platform device
 *
 * Return: 0 on success, a negative error code otherwise.
 */
static int zsr_of_init(struct zynq_servo_rproc *zsr,
		       struct platform_device *pdev)
{
	struct device *dev = &pdev->dev;
	struct device_node *np = dev->of_node;
	struct device_node *mem_np;
	struct reserved_mem *rmem;
	struct resource *res;
	int ret;

	res = platform_get_resource_byname(pdev, IORESOURCE_MEM, "control");
	zsr->ctrl = devm_ioremap_resource(dev, res);
	if (IS_ERR(zsr->ctrl))
		return PTR_ERR(zsr->ctrl);
	zsr->ocm[ZSR_OCM_CONTROL] = (struct zsr_region) {
		"control words", res->start, (u64)res->end + 1 };

	res = platform_get_resource_byname(pdev, IORESOURCE_MEM, "boot");
	zsr->boot = devm_ioremap_resource(dev, res);
	if (IS_ERR(zsr->boot))
		return PTR_ERR(zsr->boot);
	zsr->ocm[ZSR_OCM_BOOT_REG] = (struct zsr_region) {
		"CPU1 boot register", res->start, (u64)res->end + 1 };

	mem_np = of_parse_phandle(np, "memory-region", 0);
	if (!mem_np) {
		dev_err(dev, "missing memory-region (the firmware carveout)\n");
		return -EINVAL;
	}
	rmem = of_reserved_mem_lookup(mem_np);
	if (!rmem || !of_property_read_bool(mem_np, "no-map")) {
		dev_err(dev, "%pOF must be a no-map reserved-memory region\n",
			mem_np);
		of_node_put(mem_np);
		return -EINVAL;
	}
	of_node_put(mem_np);
	zsr->carveout = (struct zsr_region) {
		"carveout", rmem->base, (u64)rmem->base + rmem->size };

	if (of_property_read_u32(np, "servoamp,park-address", &zsr->park_addr) ||
	    zsr->park_addr < ZSR_OCM_BASE) {
		dev_err(dev, "servoamp,park-address missing or not in OCM\n");
		return -EINVAL;
	}
	/* the boot stub page that holds the park loop */
	zsr->ocm[ZSR_OCM_STUB] = (struct zsr_region) { "boot stub and park loop",
		zsr->park_addr & ~0xfffULL, (zsr->park_addr & ~0xfffULL) + 0x1000 };

	ret = zsr_of_region(zsr, "servoamp,ocm-mailbox",
			    &zsr->ocm[ZSR_OCM_MAILBOX], false);
	if (ret)
		return ret;
	zsr->ocm[ZSR_OCM_MAILBOX].name = "amp_lib mailbox";

	zsr->start_timeout_ms = ZSR_DEFAULT_START_TIMEOUT_MS;
	of_property_read_u32(np, "servoamp,start-timeout-ms",
			     &zsr->start_timeout_ms);
	zsr->stop_timeout_ms = ZSR_DEFAULT_STOP_TIMEOUT_MS;
	of_property_read_u32(np, "servoamp,stop-timeout-ms",
			     &zsr->stop_timeout_ms);

	if (of_find_property(np, "servoamp,slcr", NULL)) {
		zsr->slcr = syscon_regmap_lookup_by_phandle(np, "servoamp,slcr");
		if (IS_ERR(zsr->slcr)) {
			dev_err(dev, "servoamp,slcr is not a syscon\n");
			return PTR_ERR(zsr->slcr);
		}
	}

	return 0;
}

static int zsr_probe(struct platform_device *pdev)
{
	struct device *dev = &pdev->dev;
	const char *fw_name = ZSR_DEFAULT_FIRMWARE;
	struct zynq_servo_rproc *zsr;
	struct rproc *rproc;
	int ret;

	of_property_read_string(dev->of_node, "firmware-name", &fw_name);

	rproc = devm_rproc_alloc(dev, "servo-cpu1", &zsr_ops, fw_name,
				 sizeof(*zsr));
	if (!rproc)
		return -ENOMEM;

	zsr = rproc->priv;
	zsr->dev = dev;
	zsr->rproc = rproc;
	rproc->auto_boot = false;
	rproc_coredump_set_elf_info(rproc, ELFCLASS32, EM_ARM);
	platform_set_drvdata(pdev, zsr);

	ret = zsr_of_init(zsr, pdev);
	if (ret)
		return ret;

	/*
	 * CPU1 is parked by the boot stub, unless an earlier instance of this
	 * driver could not stop a firmware: its 'RUN!' is then still in the
	 * status word. Ask that firmware to park; if it does not, nothing is
	 * loaded until it does (zsr_halt()), and 'RUN!' stays for the next
	 * probe to see. Otherwise keep CPU1 parked and make the OCM words say
	 * "not running" until the first start.
	 */
	if (readl(zsr->ctrl + ZSR_STATUS_OFFSET) == ZSR_STATUS_RUNNING) {
		dev_warn(dev, "status word reads 'RUN!': a firmware may still run on CPU1, asking it to park\n");
		zsr_halt(zsr);
	}
	writel(0, zsr->boot);
	writel(ZSR_CTRL_STOP, zsr->ctrl + ZSR_CTRL_OFFSET);
	if (!zsr->cpu1_unconfirmed)
		writel(0, zsr->ctrl + ZSR_STATUS_OFFSET);

	ret = devm_rproc_add(dev, rproc);
	if (ret) {
		dev_err(dev, "rproc_add failed: %d\n", ret);
		return ret;
	}

	dev_info(dev, "servo core CPU1: carveout [0x%llx-0x%llx), park loop 0x%08x, firmware %s\n",
		 zsr->carveout.start, zsr->carveout.end, zsr->park_addr,
		 fw_name);
	return 0;
}

/**
 * report_crash_store() - user space reports that the servo core died
 * @dev: the platform device
 * @attr: the attribute
 * @buf: "watchdog" (or "1") for a watchdog expiry, "fatal" for a fatal error
 * @count: its length
 *
 * The servo core has no interrupt towards Linux that could report a hang:
 * the watchdog over its heartbeat runs in user space (servod, amp_lib's
 * AMP_E_STALLED). This file hands that verdict to remoteproc, whose
 * recovery (when enabled, the default) stops the firmware and starts it
 * again. Only while the state is "running".
 *
 * Return: @count, or -EINVAL for another word, -EBUSY when not running.
 */
static ssize_t report_crash_store(struct device *dev,
				  struct device_attribute *attr,
				  const char *buf, size_t count)
{
	struct zynq_servo_rproc *zsr = dev_get_drvdata(dev);
	enum rproc_crash_type type;

	if (sysfs_streq(buf, "watchdog") || sysfs_streq(buf, "1"))
		type = RPROC_WATCHDOG;
	else if (sysfs_streq(buf, "fatal"))
		type = RPROC_FATAL_ERROR;
	else
		return -EINVAL;

	if (zsr->rproc->state != RPROC_RUNNING)
		return -EBUSY;

	dev_warn(dev, "crash reported by user space (%s)\n",
		 type == RPROC_WATCHDOG ? "watchdog" : "fatal error");
	rproc_report_crash(zsr->rproc, type);
	return count;
}
static DEVICE_ATTR_WO(report_crash);

static struct attribute *zsr_attrs[] = {
	&dev_attr_report_crash.attr,
	NULL,
};
ATTRIBUTE_GROUPS(zsr);

static const struct of_device_id zsr_of_match[] = {
	{ .compatible = "servoamp,zynq-a9-rproc" },
	{ /* sentinel */ },
};
MODULE_DEVICE_TABLE(of, zsr_of_match);

static struct platform_driver zsr_driver = {
	.probe = zsr_probe,
	.driver = {
		.name = "zynq-servo-rproc",
		.of_match_table = zsr_of_match,
		.dev_groups = zsr_groups,
	},
};
module_platform_driver(zsr_driver);

MODULE_DESCRIPTION("Zynq-7000 CPU1 servo core remoteproc driver (servoamp)");
MODULE_AUTHOR("The servoamp authors");
MODULE_LICENSE("GPL");
