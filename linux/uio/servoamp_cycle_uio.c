// SPDX-License-Identifier: GPL-2.0-only
/*
 * The cycle interrupt as a UIO device whose wake-up of user space does not
 * wait for softirq work.
 *
 * The user-space ABI is uio_pdrv_genirq's: one map (the page holding the
 * acknowledge register; maps/map0/offset gives the register's offset),
 * read() on /dev/uioN blocks until the next interrupt and returns the event
 * count, writing 1 re-enables the interrupt after the handler masked it.
 *
 * Why not uio_pdrv_genirq itself: on a PREEMPT_RT kernel every handler
 * requested with request_irq() is force-threaded, and a forced thread runs
 * its handler with bottom halves disabled. On PREEMPT_RT that takes the
 * per-CPU softirq lock, which the Ethernet interrupt's thread holds while
 * it processes received packets: servod's wake-up then waited for that
 * work (p99 58 us, max 183 us under bulk TCP; docs/cycle.md). Here the
 * interrupt is requested with IRQF_ONESHOT and a thread function of its
 * own, which the kernel does not force-thread: the primary handler masks
 * the line in hard interrupt context, and the wake-up of the reader
 * (uio_event_notify(), whose wait-queue lock sleeps on PREEMPT_RT) runs in
 * the interrupt's thread without the softirq lock. On a kernel without
 * PREEMPT_RT the primary handler wakes the reader itself, as
 * uio_pdrv_genirq does, and the thread never runs.
 *
 * Binding: devicetree/bindings/timer/servoamp,cycle-interrupt.yaml.
 */
#include <linux/interrupt.h>
#include <linux/io.h>
#include <linux/kernel.h>
#include <linux/mm.h>
#include <linux/module.h>
#include <linux/of.h>
#include <linux/platform_device.h>
#include <linux/spinlock.h>
#include <linux/uio_driver.h>

struct cycle_uio {
	struct uio_info info;
	/* serialises the mask state against the handler */
	raw_spinlock_t lock;
	bool masked;
	int irq;
};

static irqreturn_t cycle_uio_hardirq(int irq, void *dev_id)
{
	struct cycle_uio *c = dev_id;

	/* the source stays asserted until servod acknowledges it */
	raw_spin_lock(&c->lock);
	if (!c->masked) {
		c->masked = true;
		disable_irq_nosync(irq);
	}
	raw_spin_unlock(&c->lock);

	if (IS_ENABLED(CONFIG_PREEMPT_RT))
		return IRQ_WAKE_THREAD;
	uio_event_notify(&c->info);
	return IRQ_HANDLED;
}

static irqreturn_t cycle_uio_thread(int irq, void *dev_id)
{
	struct cycle_uio *c = dev_id;

	uio_event_notify(&c->info);
	return IRQ_HANDLED;
}

/*
 * Every change of @masked to true disables the line inside the lock, and
 * every change to false enables it once, after the lock (enable_irq() is
 * not called with interrupts off): an enable never comes before the
 * disable it pairs with, so the line's disable depth stays 0 or 1.
 */
static int cycle_uio_irqcontrol(struct uio_info *info, s32 irq_on)
{
	struct cycle_uio *c = info->priv;
	unsigned long flags;
	bool enable = false;

	raw_spin_lock_irqsave(&c->lock, flags);
	if (irq_on && c->masked) {
		c->masked = false;
		enable = true;
	} else if (!irq_on && !c->masked) {
		c->masked = true;
		disable_irq_nosync(c->irq);
	}
	raw_spin_unlock_irqrestore(&c->lock, flags);
	if (enable)
		enable_irq(c->irq);
	return 0;
}

static int cycle_uio_probe(struct platform_device *pdev)
{
	struct device *dev = &pdev->dev;
	struct uio_mem *map;
	struct resource *r;
	struct cycle_uio *c;
	int ret;

	c = devm_kzalloc(dev, sizeof(*c), GFP_KERNEL);
	if (!c)
		return -ENOMEM;
	raw_spin_lock_init(&c->lock);

	r = platform_get_resource(pdev, IORESOURCE_MEM, 0);
	if (!r)
		return dev_err_probe(dev, -EINVAL, "no acknowledge register (reg)\n");
	c->irq = platform_get_irq(pdev, 0);
	if (c->irq < 0)
		return c->irq;

	/* the node's name, as uio_pdrv_genirq names it (servod looks for it) */
	c->info.name = devm_kasprintf(dev, GFP_KERNEL, "%pOFn", dev->of_node);
	if (!c->info.name)
		return -ENOMEM;
	c->info.version = "servoamp-cycle-uio 1";
	c->info.irq = UIO_IRQ_CUSTOM;
	c->info.irqcontrol = cycle_uio_irqcontrol;
	c->info.priv = c;
	map = &c->info.mem[0];
	map->name = r->name;
	map->memtype = UIO_MEM_PHYS;
	map->addr = r->start & PAGE_MASK;
	map->offs = r->start & ~PAGE_MASK;
	map->size = PAGE_ALIGN(map->offs + resource_size(r));

	ret = devm_uio_register_device(dev, &c->info);
	if (ret)
		return dev_err_probe(dev, ret, "UIO registration failed\n");

	/* IRQF_ONESHOT: a thread function of our own, never force-threaded */
	ret = devm_request_threaded_irq(dev, c->irq, cycle_uio_hardirq, cycle_uio_thread,
					IRQF_ONESHOT, c->info.name, c);
	if (ret)
		return dev_err_probe(dev, ret, "interrupt %d not available\n", c->irq);

	dev_info(dev, "cycle interrupt %d: %s\n", c->irq,
		 IS_ENABLED(CONFIG_PREEMPT_RT) ?
		 "reader woken from the interrupt's own thread" :
		 "reader woken from the hard interrupt");
	return 0;
}

static const struct of_device_id cycle_uio_of_match[] = {
	{ .compatible = "servoamp,cycle-interrupt" },
	{ /* sentinel */ },
};
MODULE_DEVICE_TABLE(of, cycle_uio_of_match);

static struct platform_driver cycle_uio_driver = {
	.probe = cycle_uio_probe,
	.driver = {
		.name = "servoamp-cycle-uio",
		.of_match_table = cycle_uio_of_match,
	},
};
module_platform_driver(cycle_uio_driver);

MODULE_DESCRIPTION("servoamp cycle interrupt as a UIO device");
MODULE_LICENSE("GPL");
