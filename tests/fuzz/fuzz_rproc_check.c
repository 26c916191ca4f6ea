// SPDX-License-Identifier: GPL-2.0-only
/*
 * fuzz_rproc_check - the servo core driver's image checks
 * (linux/remoteproc/zynq_servo_rproc_check.h, the code the module runs),
 * compiled in user space against tests/fuzz/kshim/, on arbitrary images.
 *
 * Each input is a firmware image (a heap copy of exactly its size). It
 * goes where the remoteproc core sends it: rproc_elf_sanity_check() (a
 * copy of Linux 6.1's, below), then zsr_check_image() with the board's
 * carveout and OCM ranges (devicetree/zynq-7000-servoamp.dtsi). An image
 * both accept is then used as the core uses it, and what the driver
 * promises is asserted: find_table() (a copy of the core's) finds the same
 * resource table without reading past the file, the table has trace and
 * carveout entries only, inside the carveout (a carveout at fixed
 * addresses, not FW_RSC_ADDR_ANY), every PT_LOAD segment's bytes
 * lie inside the file and its memory inside a model of the carveout (a
 * heap buffer of its size: both ends are touched), never in OCM, no two
 * segments overlap, the entry point is in one. Refusals return -EINVAL.
 * SERVOAMP_FUZZ_VERBOSE=1 prints the driver's messages.
 */
#include <errno.h>
#include <stdlib.h>

#include "zynq_servo_rproc_check.h"

#include "fuzz_assert.h"

#define CARVEOUT_START 0x1f000000ULL
#define CARVEOUT_SIZE  0x01000000ULL

static struct device fz_dev;
static const struct zsr_image_limits lim = {
	.dev = &fz_dev,
	.carveout = { "carveout", CARVEOUT_START, CARVEOUT_START + CARVEOUT_SIZE },
	.ocm = {
		[ZSR_OCM_STUB] = { "boot stub and park loop", 0xfffc0000ULL, 0xfffc1000ULL },
		[ZSR_OCM_MAILBOX] = { "amp_lib mailbox", 0xffff0000ULL, 0xffff8000ULL },
		[ZSR_OCM_CONTROL] = { "control words", 0xffff8000ULL, 0xffff8008ULL },
		[ZSR_OCM_BOOT_REG] = { "CPU1 boot register", 0xfffffff0ULL, 0xfffffff4ULL },
	},
};
static u8 *carve;	/* the carveout as the core would write it */

/* ---- the remoteproc core (Linux 6.1 remoteproc_elf_loader.c), copied:
 * the ELF32/ELF64 accessors reduced to what these two functions read ---- */
static u64 hdr_phoff(u8 class, const void *e)
{
	return class == ELFCLASS64 ? ((const struct elf64_hdr *)e)->e_phoff :
				     ((const struct elf32_hdr *)e)->e_phoff;
}

static u64 hdr_shoff(u8 class, const void *e)
{
	return class == ELFCLASS64 ? ((const struct elf64_hdr *)e)->e_shoff :
				     ((const struct elf32_hdr *)e)->e_shoff;
}

static u16 hdr_phnum(u8 class, const void *e)
{
	return class == ELFCLASS64 ? ((const struct elf64_hdr *)e)->e_phnum :
				     ((const struct elf32_hdr *)e)->e_phnum;
}

static u16 hdr_shnum(u8 class, const void *e)
{
	return class == ELFCLASS64 ? ((const struct elf64_hdr *)e)->e_shnum :
				     ((const struct elf32_hdr *)e)->e_shnum;
}

static u16 hdr_shstrndx(u8 class, const void *e)
{
	return class == ELFCLASS64 ? ((const struct elf64_hdr *)e)->e_shstrndx :
				     ((const struct elf32_hdr *)e)->e_shstrndx;
}

static u32 size_of_shdr(u8 class)
{
	return class == ELFCLASS64 ? sizeof(struct elf64_shdr) : sizeof(struct elf32_shdr);
}

static u64 sh_offset(u8 class, const void *s)
{
	return class == ELFCLASS64 ? ((const struct elf64_shdr *)s)->sh_offset :
				     ((const struct elf32_shdr *)s)->sh_offset;
}

static u64 sh_size(u8 class, const void *s)
{
	return class == ELFCLASS64 ? ((const struct elf64_shdr *)s)->sh_size :
				     ((const struct elf32_shdr *)s)->sh_size;
}

static u32 sh_name(u8 class, const void *s)
{
	return class == ELFCLASS64 ? ((const struct elf64_shdr *)s)->sh_name :
				     ((const struct elf32_shdr *)s)->sh_name;
}

static int core_sanity_check(const struct firmware *fw)
{
	const struct elf32_hdr *ehdr;
	u32 shdr_size;
	u64 phoff, shoff;
	u8 class;
	u16 phnum;

	if (fw->size < sizeof(struct elf32_hdr))
		return -EINVAL;
	ehdr = (const struct elf32_hdr *)fw->data;
	if (memcmp(ehdr->e_ident, ELFMAG, SELFMAG))
		return -EINVAL;
	class = ehdr->e_ident[EI_CLASS];
	if (class != ELFCLASS32 && class != ELFCLASS64)
		return -EINVAL;
	if (class == ELFCLASS64 && fw->size < sizeof(struct elf64_hdr))
		return -EINVAL;
	if (ehdr->e_ident[EI_DATA] != ELFDATA2LSB)
		return -EINVAL;
	phoff = hdr_phoff(class, fw->data);
	shoff = hdr_shoff(class, fw->data);
	phnum = hdr_phnum(class, fw->data);
	shdr_size = size_of_shdr(class);
	if (fw->size < shoff + shdr_size)
		return -EINVAL;
	if (phnum == 0)
		return -EINVAL;
	if (phoff > fw->size)
		return -EINVAL;
	return 0;
}

static const void *core_find_table(const struct firmware *fw)
{
	const u8 *elf_data = fw->data;
	u8 class = elf_data[EI_CLASS];
	const void *shdr, *name_table_shdr;
	const char *name_table;
	u16 shnum = hdr_shnum(class, elf_data);
	u32 shdr_size = size_of_shdr(class);
	u16 shstrndx = hdr_shstrndx(class, elf_data);
	int i;

	shdr = elf_data + hdr_shoff(class, elf_data);
	name_table_shdr = (const u8 *)shdr + (shstrndx * shdr_size);
	name_table = (const char *)elf_data + sh_offset(class, name_table_shdr);

	for (i = 0; i < shnum; i++, shdr = (const u8 *)shdr + shdr_size) {
		u64 size = sh_size(class, shdr);
		u64 offset = sh_offset(class, shdr);
		u32 name = sh_name(class, shdr);
		const struct resource_table *table;

		if (strcmp(name_table + name, ".resource_table"))
			continue;
		table = (const struct resource_table *)(elf_data + offset);
		if (offset + size > fw->size || offset + size < size)
			return NULL;
		if (sizeof(struct resource_table) > size)
			return NULL;
		if (table->ver != 1)
			return NULL;
		if (table->reserved[0] || table->reserved[1])
			return NULL;
		if (struct_size(table, offset, table->num) > size)
			return NULL;
		return shdr;
	}
	return NULL;
}

/* ---- what the core does with an accepted image, and what must hold ---- */
static bool in_carveout(u64 start, u64 len)
{
	return start >= lim.carveout.start && start + len <= lim.carveout.end;
}

static int core_rsc_entry(u32 type, void *rsc, int offset, int avail, void *data)
{
	(void)offset;
	(void)data;
	FZ_ASSERT(avail >= 0);
	if (type == RSC_TRACE) {
		const struct fw_rsc_trace *t = rsc;

		FZ_ASSERT(avail >= (int)sizeof(*t));
		/* rproc_da_to_va(da, len) in the carveout: the whole buffer */
		FZ_ASSERT(in_carveout(t->da, t->len));
		if (t->len)
			FZ_ASSERT(carve[t->da - CARVEOUT_START] == 0 &&
				  carve[t->da - CARVEOUT_START + t->len - 1u] == 0);
	} else {
		/* the board's types only: no RSC_DEVMEM, RSC_VDEV, vendor or
		 * unknown type; a carveout at fixed addresses in the carveout */
		const struct fw_rsc_carveout *c = rsc;

		FZ_ASSERT(type == RSC_CARVEOUT);
		FZ_ASSERT(avail >= (int)sizeof(*c));
		FZ_ASSERT(c->da != (u32)FW_RSC_ADDR_ANY && c->pa != (u32)FW_RSC_ADDR_ANY);
		FZ_ASSERT(in_carveout(c->da, c->len));
	}
	return 0;
}

static void use_accepted(const struct firmware *fw)
{
	const struct elf32_hdr *ehdr = (const struct elf32_hdr *)fw->data;
	const struct elf32_phdr *ph;
	const struct elf32_shdr *rsc = zsr_rsc_section(fw);
	const void *found = core_find_table(fw);
	bool entry = false;
	int i, j;

	FZ_ASSERT(ehdr->e_ident[EI_CLASS] == ELFCLASS32);
	/* the core takes the table the driver checked, or none when the
	 * driver saw none (it may still refuse one: a version it does not know) */
	FZ_ASSERT(!found || found == (const void *)rsc);
	if (found) {
		u8 *copy = malloc(rsc->sh_size);	/* kmemdup() */

		FZ_ASSERT(copy);
		memcpy(copy, fw->data + rsc->sh_offset, rsc->sh_size);
		FZ_ASSERT(rsc_table_for_each_entry((struct resource_table *)copy,
						   rsc->sh_size, &fz_dev,
						   core_rsc_entry, NULL) == 0);
		FZ_ASSERT(in_carveout(rsc->sh_addr, rsc->sh_size));
		free(copy);
	}

	ph = (const struct elf32_phdr *)(fw->data + ehdr->e_phoff);
	for (i = 0; i < ehdr->e_phnum; i++) {
		u64 off;

		if (ph[i].p_type != PT_LOAD || !ph[i].p_memsz)
			continue;
		/* rproc_elf_load_segments(): memcpy(da_to_va(paddr), data + offset, filesz) */
		FZ_ASSERT(ph[i].p_filesz <= ph[i].p_memsz);
		FZ_ASSERT((u64)ph[i].p_offset + ph[i].p_filesz <= fw->size);
		FZ_ASSERT(in_carveout(ph[i].p_paddr, ph[i].p_memsz));
		for (j = 0; j < ZSR_OCM_NUM; j++)
			FZ_ASSERT(!zsr_overlaps(ph[i].p_paddr, (u64)ph[i].p_paddr + ph[i].p_memsz,
						&lim.ocm[j]));
		off = ph[i].p_paddr - CARVEOUT_START;
		FZ_ASSERT(carve[off] == 0 && carve[off + ph[i].p_memsz - 1u] == 0);
		if (ph[i].p_filesz)	/* the last byte the copy reads */
			(void)*(const volatile u8 *)&fw->data[ph[i].p_offset + ph[i].p_filesz - 1u];
		for (j = 0; j < i; j++)
			if (ph[j].p_type == PT_LOAD && ph[j].p_memsz)
				FZ_ASSERT((u64)ph[j].p_paddr + ph[j].p_memsz <= ph[i].p_paddr ||
					  (u64)ph[i].p_paddr + ph[i].p_memsz <= ph[j].p_paddr);
		if (ehdr->e_entry >= ph[i].p_paddr &&
		    ehdr->e_entry < (u64)ph[i].p_paddr + ph[i].p_memsz)
			entry = true;
	}
	FZ_ASSERT(entry);
}

int LLVMFuzzerInitialize(int *argc, char ***argv);
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerInitialize(int *argc, char ***argv)
{
	const char *v = getenv("SERVOAMP_FUZZ_VERBOSE");

	(void)argc;
	(void)argv;
	fz_dev.verbose = v && *v == '1';
	carve = calloc(1, CARVEOUT_SIZE);
	FZ_ASSERT(carve);
	return 0;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	u8 *copy = malloc(size ? size : 1u);
	struct firmware fw = { size, copy };
	int ret;

	FZ_ASSERT(copy);
	memcpy(copy, data, size);
	ret = core_sanity_check(&fw);
	if (!ret)
		ret = zsr_check_image(&lim, "fuzz.elf", &fw);
	FZ_ASSERT(ret == 0 || ret == -EINVAL);
	if (!ret) {
		use_accepted(&fw);
		kshim_dev_printk(&fz_dev, "fuzz_rproc_check: image accepted\n");
	}
	free(copy);
	return 0;
}
