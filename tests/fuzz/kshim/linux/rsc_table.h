/* SPDX-License-Identifier: GPL-2.0-only */
/*
 * User-space stand-in for <linux/rsc_table.h>: the resource table layout
 * and rsc_table_for_each_entry() as Linux 6.1 (Debian 6.1.192) has them,
 * copied (only the entries the driver checks).
 */
#ifndef KSHIM_LINUX_RSC_TABLE_H
#define KSHIM_LINUX_RSC_TABLE_H
#include <errno.h>
#include <linux/device.h>
#include <linux/types.h>

struct resource_table {
	u32 ver;
	u32 num;
	u32 reserved[2];
	u32 offset[];
} __packed;

struct fw_rsc_hdr {
	u32 type;
	u8 data[];
} __packed;

enum fw_resource_type {
	RSC_CARVEOUT = 0,
	RSC_DEVMEM = 1,
	RSC_TRACE = 2,
	RSC_VDEV = 3,
	RSC_LAST = 4,
	RSC_VENDOR_START = 128,
	RSC_VENDOR_END = 512,
};

#define FW_RSC_ADDR_ANY (-1)

struct fw_rsc_carveout {
	u32 da;
	u32 pa;
	u32 len;
	u32 flags;
	u32 reserved;
	u8 name[32];
} __packed;

struct fw_rsc_trace {
	u32 da;
	u32 len;
	u32 reserved;
	u8 name[32];
} __packed;

static inline int rsc_table_for_each_entry(struct resource_table *table,
					   size_t table_sz,
					   struct device *dev,
					   int (*cb)(u32 type, void *rsc,
						     int offset, int avail,
						     void *data),
					   void *data)
{
	int i, ret;

	for (i = 0; (u32)i < table->num; i++) {
		u32 offset = table->offset[i];
		struct fw_rsc_hdr *hdr;
		int avail, rsc_offset;
		void *rsc;

		if (offset < sizeof(*table) || offset >= table_sz ||
		    table_sz - offset < sizeof(*hdr)) {
			dev_err(dev, "rsc table is truncated\n");
			return -EINVAL;
		}

		hdr = (void *)((u8 *)table + offset);
		avail = table_sz - offset - sizeof(*hdr);
		rsc_offset = offset + sizeof(*hdr);
		rsc = (void *)((u8 *)hdr + sizeof(*hdr));

		ret = cb(hdr->type, rsc, rsc_offset, avail, data);
		if (ret)
			return ret;
	}

	return 0;
}
#endif
