/* SPDX-License-Identifier: GPL-2.0-only */
/*
 * The servo core driver's checks of a firmware image: what the remoteproc
 * core's rproc_elf_sanity_check() leaves open and what is specific to this
 * board (ELF32 ARM executable, header tables, section names, PT_LOAD
 * segments against the carveout and OCM, the resource table and its
 * entries). Kept apart from zynq_servo_rproc.c so that the same code is
 * compiled into the module and, with a small user-space stand-in for the
 * kernel headers it includes (tests/fuzz/kshim/), into the fuzz harness
 * tests/fuzz/fuzz_rproc_check.c. Included by zynq_servo_rproc.c only.
 *
 * Copyright (C) 2026 The servoamp authors
 */
#ifndef ZYNQ_SERVO_RPROC_CHECK_H
#define ZYNQ_SERVO_RPROC_CHECK_H

#include <linux/align.h>
#include <linux/device.h>
#include <linux/elf.h>
#include <linux/firmware.h>
#include <linux/overflow.h>
#include <linux/rsc_table.h>
#include <linux/string.h>
#include <linux/types.h>

/* On-chip memory of the Zynq-7000, mapped high (0xfffc0000-0xffffffff) */
#define ZSR_OCM_BASE		0xfffc0000ULL
#define ZSR_OCM_END		0x100000000ULL	/* exclusive */

/* no servo firmware has more PT_LOAD segments (the overlap check is O(n^2)) */
#define ZSR_MAX_LOAD_SEGMENTS		32

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
 * struct zsr_image_limits - where this board lets a firmware image go
 * @dev: the device that logs the refusals
 * @carveout: the reserved-memory region the firmware runs from
 * @ocm: OCM ranges the firmware must not load into, with their names
 */
struct zsr_image_limits {
	struct device *dev;
	struct zsr_region carveout;
	struct zsr_region ocm[ZSR_OCM_NUM];
};

static bool zsr_overlaps(u64 start, u64 end, const struct zsr_region *r)
{
	return start < r->end && r->start < end;
}

/**
 * zsr_ocm_owner() - name the OCM area that a range overlaps
 * @lim: where this board lets an image go
 * @start: first address of the range
 * @end: first address after the range
 *
 * Return: a description of the first driver-known OCM area overlapped by
 * [@start, @end), "on-chip memory" for any other OCM address, or NULL when
 * the range does not touch OCM at all.
 */
static const char *zsr_ocm_owner(const struct zsr_image_limits *lim, u64 start,
				 u64 end)
{
	const struct zsr_region ocm = { NULL, ZSR_OCM_BASE, ZSR_OCM_END };
	int i;

	for (i = 0; i < ZSR_OCM_NUM; i++)
		if (lim->ocm[i].end && zsr_overlaps(start, end, &lim->ocm[i]))
			return lim->ocm[i].name;

	return zsr_overlaps(start, end, &ocm) ? "on-chip memory" : NULL;
}

/**
 * zsr_check_ehdr() - what the core's rproc_elf_sanity_check() leaves open
 * @lim: where this board lets an image go
 * @name: the image name, for messages
 * @fw: an image that passed rproc_elf_sanity_check()
 *
 * Return: 0 for an ELF32 ARM executable whose program and section header
 * tables lie inside the file at 4-byte aligned offsets, -EINVAL otherwise.
 */
static int zsr_check_ehdr(const struct zsr_image_limits *lim, const char *name,
			  const struct firmware *fw)
{
	const struct elf32_hdr *ehdr = (const struct elf32_hdr *)fw->data;
	struct device *dev = lim->dev;
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
	/*
	 * The core and the driver read the header tables in place, as arrays
	 * of structures of u32: at a misaligned offset every such read is
	 * undefined (and a trap on ARM for LDRD/LDM).
	 */
	if (!IS_ALIGNED(ehdr->e_phoff, sizeof(u32)) ||
	    !IS_ALIGNED(ehdr->e_shoff, sizeof(u32))) {
		dev_err(dev, "%s: header tables at misaligned file offsets (program 0x%x, section 0x%x), not 4-byte aligned\n",
			name, ehdr->e_phoff, ehdr->e_shoff);
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
	/*
	 * Without section headers the name table index must be SHN_UNDEF: the
	 * core's find_table() reads the header at that index whatever e_shnum
	 * says (for every image, from rproc_elf_find_loaded_rsc_table()).
	 */
	if (!ehdr->e_shnum) {
		if (ehdr->e_shstrndx == SHN_UNDEF)
			return 0;
		dev_err(dev, "%s: no section headers, but section name table index %u\n",
			name, ehdr->e_shstrndx);
		return -EINVAL;
	}
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
 * @lim: where this board lets an image go
 * @name: the image name, for messages
 * @fw: an image that passed zsr_check_ehdr()
 *
 * rproc_elf_load_segments() loads each segment at its physical address, in
 * table order: overlapping segments would overwrite each other.
 *
 * Return: 0 if the segments can be loaded, -EINVAL otherwise.
 */
static int zsr_check_segments(const struct zsr_image_limits *lim, const char *name,
			      const struct firmware *fw)
{
	const struct elf32_hdr *ehdr = (const struct elf32_hdr *)fw->data;
	const struct elf32_phdr *phdr, *prev;
	struct device *dev = lim->dev;
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
		owner = zsr_ocm_owner(lim, start, end);
		if (owner) {
			dev_err(dev, "%s: segment %d [0x%llx-0x%llx) overlaps OCM (%s), which the firmware does not own\n",
				name, i, start, end, owner);
			return -EINVAL;
		}
		if (start < lim->carveout.start || end > lim->carveout.end) {
			dev_err(dev, "%s: segment %d [0x%llx-0x%llx) is outside the carveout [0x%llx-0x%llx)\n",
				name, i, start, end, lim->carveout.start,
				lim->carveout.end);
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
 * @lim: where this board lets an image go
 * @name: the image name, for messages
 * @fw: an image that passed zsr_check_ehdr()
 *
 * The core's find_table() strcmp()s the name of every section, at the name
 * table's file offset plus sh_name, with no bound: the name table must lie
 * inside the file and every name must start, and end with a NUL, inside it.
 *
 * Return: 0 if all names are bounded, -EINVAL otherwise.
 */
static int zsr_check_section_names(const struct zsr_image_limits *lim,
				   const char *name, const struct firmware *fw)
{
	const struct elf32_hdr *ehdr = (const struct elf32_hdr *)fw->data;
	const struct elf32_shdr *shdr, *strtab;
	struct device *dev = lim->dev;
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
 * @lim: where this board lets an image go
 * @da: first device address
 * @len: length in bytes
 *
 * In u64, so that a @len near 4 GiB cannot wrap the sum (the core's
 * rproc_da_to_va() adds them in 32 bits).
 */
static bool zsr_in_carveout(const struct zsr_image_limits *lim, u32 da,
			    u32 len)
{
	return da >= lim->carveout.start &&
	       (u64)da + len <= lim->carveout.end;
}

/**
 * struct zsr_rsc_check - the walk of a resource table's entries
 * @lim: where this board lets an image go
 * @name: the image name, for messages
 * @index: the index of the entry being checked
 */
struct zsr_rsc_check {
	const struct zsr_image_limits *lim;
	const char *name;
	int index;
};

/**
 * zsr_rsc_type_refused() - why an entry of this type has no place here
 * @type: the entry's type
 *
 * The servo firmware announces its trace buffer (RSC_TRACE) and may
 * describe its memory (RSC_CARVEOUT, checked with its addresses). Every
 * other type would make the remoteproc core act for a firmware of another
 * board, or be ignored by it with a warning.
 *
 * Return: the reason, or NULL for RSC_TRACE and RSC_CARVEOUT.
 */
static const char *zsr_rsc_type_refused(u32 type)
{
	if (type == RSC_TRACE || type == RSC_CARVEOUT)
		return NULL;
	if (type == RSC_DEVMEM)
		return "RSC_DEVMEM maps device memory, and the servo core has no IOMMU";
	if (type == RSC_VDEV)
		return "RSC_VDEV is a virtio device; this board talks through OCM mailboxes";
	if (type >= RSC_VENDOR_START && type <= RSC_VENDOR_END)
		return "vendor-specific, and this driver handles no vendor resource";
	return "unknown to the remoteproc core";
}

/* rsc_table_for_each_entry() callback: only the types the board uses, inside the carveout */
static int zsr_check_rsc_entry(u32 type, void *rsc, int offset, int avail,
			       void *data)
{
	struct zsr_rsc_check *c = data;
	const struct zsr_image_limits *lim = c->lim;
	const struct fw_rsc_carveout *mem = rsc;
	const struct fw_rsc_trace *trace = rsc;
	int index = c->index++;
	const char *why;

	why = zsr_rsc_type_refused(type);
	if (why) {
		dev_err(lim->dev, "%s: resource entry %d (type %u) refused: %s\n",
			c->name, index, type, why);
		return -EINVAL;
	}

	switch (type) {
	case RSC_TRACE:
		if (avail < (int)sizeof(*trace)) {
			dev_err(lim->dev, "%s: trace entry at offset %d is truncated\n",
				c->name, offset);
			return -EINVAL;
		}
		if (!zsr_in_carveout(lim, trace->da, trace->len)) {
			dev_err(lim->dev, "%s: trace buffer '%.32s' [0x%x +0x%x) is not inside the carveout [0x%llx-0x%llx)\n",
				c->name, (const char *)trace->name, trace->da,
				trace->len, lim->carveout.start,
				lim->carveout.end);
			return -EINVAL;
		}
		break;
	case RSC_CARVEOUT:
		if (avail < (int)sizeof(*mem)) {
			dev_err(lim->dev, "%s: carveout entry at offset %d is truncated\n",
				c->name, offset);
			return -EINVAL;
		}
		/*
		 * FW_RSC_ADDR_ANY would have the core allocate memory anywhere
		 * (dma_alloc_coherent) and write its address into the table:
		 * the servo firmware is linked to run from the carveout.
		 */
		if (mem->da == (u32)FW_RSC_ADDR_ANY ||
		    mem->pa == (u32)FW_RSC_ADDR_ANY) {
			dev_err(lim->dev, "%s: resource entry %d (type %u) refused: carveout '%.32s' with %s FW_RSC_ADDR_ANY, but the firmware runs from the carveout [0x%llx-0x%llx) at fixed addresses\n",
				c->name, index, type, (const char *)mem->name,
				mem->da == (u32)FW_RSC_ADDR_ANY ? "da" : "pa",
				lim->carveout.start, lim->carveout.end);
			return -EINVAL;
		}
		if (!zsr_in_carveout(lim, mem->da, mem->len)) {
			dev_err(lim->dev, "%s: carveout entry '%.32s' [0x%x +0x%x) is not inside the carveout [0x%llx-0x%llx)\n",
				c->name, (const char *)mem->name, mem->da,
				mem->len, lim->carveout.start,
				lim->carveout.end);
			return -EINVAL;
		}
		break;
	}

	return 0;
}

/**
 * zsr_check_rsc_table() - the resource table and its entries fit the board
 * @lim: where this board lets an image go
 * @name: the image name, for messages
 * @fw: the image
 * @sh: its .resource_table section
 *
 * The core checks the table's header when it reads it; the driver checks
 * first that it can walk the table, then that the table is loaded into the
 * carveout (the core copies it there before the start), that it has only
 * the entry types the board uses (RSC_TRACE, RSC_CARVEOUT at a fixed
 * address: no RSC_DEVMEM, RSC_VDEV, vendor or unknown type) and that every
 * trace buffer and carveout entry lies inside the carveout.
 *
 * Return: 0 if the table fits, -EINVAL otherwise.
 */
static int zsr_check_rsc_table(const struct zsr_image_limits *lim, const char *name,
			       const struct firmware *fw,
			       const struct elf32_shdr *sh)
{
	struct zsr_rsc_check c = { lim, name, 0 };
	struct device *dev = lim->dev;
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
	if (!zsr_in_carveout(lim, sh->sh_addr, sh->sh_size)) {
		dev_err(dev, "%s: resource table [0x%x-0x%llx) is outside the carveout [0x%llx-0x%llx)\n",
			name, sh->sh_addr, (u64)sh->sh_addr + sh->sh_size,
			lim->carveout.start, lim->carveout.end);
		return -EINVAL;
	}

	return rsc_table_for_each_entry(table, sh->sh_size, dev,
					zsr_check_rsc_entry, &c);
}

/**
 * zsr_check_image() - what rproc_elf_sanity_check() leaves to the driver
 * @lim: where this board lets an image go
 * @name: the image name, for messages
 * @fw: an image that passed rproc_elf_sanity_check()
 *
 * ELF32 ARM executable, header tables inside the file, PT_LOAD segments
 * inside the file and the carveout, never in OCM, not overlapping, the
 * entry point in one of them, section names bounded by the name table, and
 * the resource table (if any) and its entries inside the carveout, of the
 * types the board uses only. Every refusal logs the reason.
 *
 * Return: 0 if the image can be loaded, -EINVAL otherwise.
 */
static int zsr_check_image(const struct zsr_image_limits *lim,
			   const char *name, const struct firmware *fw)
{
	const struct elf32_shdr *rsc;
	int ret;

	ret = zsr_check_ehdr(lim, name, fw);
	if (ret)
		return ret;
	ret = zsr_check_segments(lim, name, fw);
	if (ret)
		return ret;
	ret = zsr_check_section_names(lim, name, fw);
	if (ret)
		return ret;

	rsc = zsr_rsc_section(fw);
	if (rsc)
		return zsr_check_rsc_table(lim, name, fw, rsc);

	return 0;
}

#endif /* ZYNQ_SERVO_RPROC_CHECK_H */
