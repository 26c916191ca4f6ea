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
 * only stores that register: an emulated CPU1 keeps running.
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
#include <linux/regmap.h>
#include <linux/remoteproc.h>
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
 * zsr_sanity_check() - refuse any image the servo core cannot run
 * @rproc: the remote processor handle
 * @fw: the firmware image
 *
 * Every refusal logs the reason. Checks: ELF magic, ELF32, little-endian,
 * EM_ARM, executable, header tables inside the file, every PT_LOAD segment
 * inside the file and inside the carveout (never in OCM), and the entry
 * point inside the carveout.
 *
 * Return: 0 if the image can be loaded, -EINVAL otherwise.
 */
static int zsr_sanity_check(struct rproc *rproc, const struct firmware *fw)
{
	struct zynq_servo_rproc *zsr = rproc->priv;
	struct device *dev = zsr->dev;
	const char *name = rproc->firmware;
	const struct elf32_hdr *ehdr;
	const struct elf32_phdr *phdr;
	u64 start, end, off_end;
	const char *owner;
	bool entry_ok = false;
	int i;

	if (fw->size < EI_NIDENT || memcmp(fw->data, ELFMAG, SELFMAG)) {
		dev_err(dev, "%s: not an ELF file (bad magic)\n", name);
		return -EINVAL;
	}
	if (fw->data[EI_CLASS] != ELFCLASS32) {
		dev_err(dev, "%s: wrong ELF class %u, the Cortex-A9 servo core needs ELF32\n",
			name, fw->data[EI_CLASS]);
		return -EINVAL;
	}
	if (fw->size < sizeof(*ehdr)) {
		dev_err(dev, "%s: truncated: %zu bytes, smaller than the ELF header\n",
			name, fw->size);
		return -EINVAL;
	}
	ehdr = (const struct elf32_hdr *)fw->data;
	if (ehdr->e_ident[EI_DATA] != ELFDATA2LSB) {
		dev_err(dev, "%s: not little-endian\n", name);
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
	if (!ehdr->e_phnum || ehdr->e_phentsize != sizeof(*phdr)) {
		dev_err(dev, "%s: no program headers, or entry size %u is not %zu\n",
			name, ehdr->e_phentsize, sizeof(*phdr));
		return -EINVAL;
	}
	off_end = (u64)ehdr->e_phoff + (u64)ehdr->e_phnum * sizeof(*phdr);
	if (off_end > fw->size) {
		dev_err(dev, "%s: truncated: program headers end at %llu, file has %zu bytes\n",
			name, off_end, fw->size);
		return -EINVAL;
	}
	if (ehdr->e_shnum) {
		off_end = (u64)ehdr->e_shoff +
			  (u64)ehdr->e_shnum * sizeof(struct elf32_shdr);
		if (ehdr->e_shentsize != sizeof(struct elf32_shdr) ||
		    ehdr->e_shstrndx >= ehdr->e_shnum) {
			dev_err(dev, "%s: malformed section header table\n",
				name);
			return -EINVAL;
		}
		if (off_end > fw->size) {
			dev_err(dev, "%s: truncated: section headers end at %llu, file has %zu bytes\n",
				name, off_end, fw->size);
			return -EINVAL;
		}
	}

	phdr = (const struct elf32_phdr *)(fw->data + ehdr->e_phoff);
	for (i = 0; i < ehdr->e_phnum; i++, phdr++) {
		if (phdr->p_type != PT_LOAD || !phdr->p_memsz)
			continue;
		if (phdr->p_filesz > phdr->p_memsz) {
			dev_err(dev, "%s: segment %d: file size 0x%x larger than memory size 0x%x\n",
				name, i, phdr->p_filesz, phdr->p_memsz);
			return -EINVAL;
		}
		off_end = (u64)phdr->p_offset + phdr->p_filesz;
		if (off_end > fw->size) {
			dev_err(dev, "%s: truncated: segment %d needs bytes up to %llu, file has %zu\n",
				name, i, off_end, fw->size);
			return -EINVAL;
		}
		/* rproc_elf_load_segments() loads at the physical address */
		start = phdr->p_paddr;
		end = start + phdr->p_memsz;
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
 * zsr_has_rsc_section() - tell whether the image has a .resource_table
 * @fw: a firmware image that passed zsr_sanity_check()
 *
 * Return: true when a section named ".resource_table" exists.
 */
static bool zsr_has_rsc_section(const struct firmware *fw)
{
	const struct elf32_hdr *ehdr = (const struct elf32_hdr *)fw->data;
	const struct elf32_shdr *shdr, *strtab;
	const char *names;
	size_t len = sizeof(".resource_table");
	int i;

	if (!ehdr->e_shnum)
		return false;

	shdr = (const struct elf32_shdr *)(fw->data + ehdr->e_shoff);
	strtab = &shdr[ehdr->e_shstrndx];
	if ((u64)strtab->sh_offset + strtab->sh_size > fw->size)
		return false;
	names = (const char *)fw->data + strtab->sh_offset;

	for (i = 0; i < ehdr->e_shnum; i++)
		if ((u64)shdr[i].sh_name + len <= strtab->sh_size &&
		    !memcmp(names + shdr[i].sh_name, ".resource_table", len))
			return true;

	return false;
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

	if (zsr_has_rsc_section(fw)) {
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
 * zsr_reset_cpu1() - reset CPU1 through the SLCR after a failed stop
 * @zsr: the servo core
 *
 * On a real Zynq-7000, CPU1 leaves reset in the boot ROM, which waits on the
 * (already zeroed) boot register: it is parked again. QEMU only stores
 * A9_CPU_RST_CTRL, so an emulated CPU1 is not affected by this write.
 */
static void zsr_reset_cpu1(struct zynq_servo_rproc *zsr)
{
	const u32 mask = ZSR_A9_RST1 | ZSR_A9_CLKSTOP1;
	int ret;

	if (!zsr->slcr) {
		dev_err(zsr->dev, "no SLCR described: CPU1 cannot be reset\n");
		return;
	}

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
	return;

err:
	dev_err(zsr->dev, "SLCR write failed: %d\n", ret);
}

/**
 * zsr_park() - ask the firmware to return to the park loop and wait for it
 * @zsr: the servo core
 *
 * Return: 0 when the firmware reported 'PRKD', -ETIMEDOUT otherwise.
 */
static int zsr_park(struct zynq_servo_rproc *zsr)
{
	u32 status;

	/* the park loop must find no entry point once the firmware is there */
	writel(0, zsr->boot);
	writel(ZSR_CTRL_STOP, zsr->ctrl + ZSR_CTRL_OFFSET);
	dsb(ishst);
	sev();

	return readl_poll_timeout(zsr->ctrl + ZSR_STATUS_OFFSET, status,
				  status == ZSR_STATUS_PARKED, ZSR_POLL_US,
				  zsr->stop_timeout_ms * USEC_PER_MSEC);
}

/**
 * zsr_stop() - cooperative stop of the servo firmware
 * @rproc: the remote processor handle
 *
 * See the comment at the top of this file. A firmware that does not park in
 * time is reset through the SLCR (real hardware only) and the stop still
 * succeeds, so that a new firmware can be started afterwards.
 *
 * Return: 0.
 */
static int zsr_stop(struct rproc *rproc)
{
	struct zynq_servo_rproc *zsr = rproc->priv;
	u32 status;

	if (zsr_park(zsr)) {
		status = readl(zsr->ctrl + ZSR_STATUS_OFFSET);
		dev_err(zsr->dev, "firmware did not park within %u ms (status 0x%08x): resetting CPU1\n",
			zsr->stop_timeout_ms, status);
		zsr_reset_cpu1(zsr);
	}

	return 0;
}

/**
 * zsr_start() - release CPU1 from the park loop into the loaded firmware
 * @rproc: the remote processor handle
 *
 * Return: 0 when the firmware reported 'RUN!' in time, -ETIMEDOUT
 * otherwise (CPU1 is then asked to park, or reset).
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
		goto err_stop;
	}

	dev_info(zsr->dev, "CPU1 running firmware at 0x%08x (RUN! after %lld us)\n",
		 entry, ktime_us_delta(ktime_get(), t0));
	return 0;

err_stop:
	if (zsr_park(zsr))
		zsr_reset_cpu1(zsr);
	return ret;
}

static const struct rproc_ops zsr_ops = {
	.start			= zsr_start,
	.stop			= zsr_stop,
	.parse_fw		= zsr_parse_fw,
	.sanity_check		= zsr_sanity_check,
	.get_boot_addr		= rproc_elf_get_boot_addr,
	.load			= rproc_elf_load_segments,
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
	 * CPU1 is parked by the boot stub. Keep it there and make the OCM
	 * words say "not running" until the first start.
	 */
	writel(0, zsr->boot);
	writel(ZSR_CTRL_STOP, zsr->ctrl + ZSR_CTRL_OFFSET);
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
