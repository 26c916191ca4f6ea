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

/* the image checks, shared with the user-space fuzz harness */
#include "zynq_servo_rproc_check.h"

/* SLCR: CPU1 reset and clock stop, used only when a stop times out */
#define ZSR_SLCR_A9_CPU_RST_CTRL	0x244
#define ZSR_A9_RST1			BIT(1)
#define ZSR_A9_CLKSTOP1			BIT(5)

#define ZSR_DEFAULT_START_TIMEOUT_MS	1000
#define ZSR_DEFAULT_STOP_TIMEOUT_MS	500
#define ZSR_POLL_US			100
/* how long 'PRKD' may still take to appear after an SLCR reset */
#define ZSR_RESET_CONFIRM_MS		50
#define ZSR_DEFAULT_FIRMWARE		"servoamp-rpu.elf"

/**
 * struct zynq_servo_rproc - state of one servo core
 * @dev: the platform device
 * @rproc: the remoteproc handle
 * @ctrl: OCM control (offset 0) and status (offset 4) words
 * @boot: the CPU1 boot register (0xfffffff0)
 * @slcr: SLCR regmap for the CPU1 reset, or NULL when not described
 * @lim: the carveout and the OCM ranges, for the image checks
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
	struct zsr_image_limits lim;
	u32 park_addr;
	u32 start_timeout_ms;
	u32 stop_timeout_ms;
	bool cpu1_unconfirmed;
};

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
 * zsr_sanity_check() - refuse any image the servo core cannot run
 * @rproc: the remote processor handle
 * @fw: the firmware image
 *
 * Nothing is loaded while a stop of CPU1 is unconfirmed. Then the core's
 * rproc_elf_sanity_check() (magic, class, endianness, a first look at the
 * header tables), then what is specific to this board: zsr_check_image()
 * in zynq_servo_rproc_check.h. Every refusal logs the reason.
 *
 * Return: 0 if the image can be loaded, a negative error code otherwise.
 */
static int zsr_sanity_check(struct rproc *rproc, const struct firmware *fw)
{
	struct zynq_servo_rproc *zsr = rproc->priv;
	const char *name = rproc->firmware;
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

	return zsr_check_image(&zsr->lim, name, fw);
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
				   (dma_addr_t)zsr->lim.carveout.start,
				   zsr->lim.carveout.end - zsr->lim.carveout.start,
				   (u32)zsr->lim.carveout.start, zsr_mem_alloc,
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
	zsr->lim.ocm[ZSR_OCM_CONTROL] = (struct zsr_region) {
		"control words", res->start, (u64)res->end + 1 };

	res = platform_get_resource_byname(pdev, IORESOURCE_MEM, "boot");
	zsr->boot = devm_ioremap_resource(dev, res);
	if (IS_ERR(zsr->boot))
		return PTR_ERR(zsr->boot);
	zsr->lim.ocm[ZSR_OCM_BOOT_REG] = (struct zsr_region) {
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
	zsr->lim.carveout = (struct zsr_region) {
		"carveout", rmem->base, (u64)rmem->base + rmem->size };

	if (of_property_read_u32(np, "servoamp,park-address", &zsr->park_addr) ||
	    zsr->park_addr < ZSR_OCM_BASE) {
		dev_err(dev, "servoamp,park-address missing or not in OCM\n");
		return -EINVAL;
	}
	/* the boot stub page that holds the park loop */
	zsr->lim.ocm[ZSR_OCM_STUB] = (struct zsr_region) { "boot stub and park loop",
		zsr->park_addr & ~0xfffULL, (zsr->park_addr & ~0xfffULL) + 0x1000 };

	ret = zsr_of_region(zsr, "servoamp,ocm-mailbox",
			    &zsr->lim.ocm[ZSR_OCM_MAILBOX], false);
	if (ret)
		return ret;
	zsr->lim.ocm[ZSR_OCM_MAILBOX].name = "amp_lib mailbox";

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
	zsr->lim.dev = dev;
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
		 zsr->lim.carveout.start, zsr->lim.carveout.end, zsr->park_addr,
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
