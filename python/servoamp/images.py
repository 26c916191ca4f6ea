"""The images of a boot, built by the project's cached build scripts (kernel,
TF-A, initramfs, firmware) or here when cheap (boot stubs, DTB). Part of the
launcher that :mod:`servoamp.qemu` re-exports."""

from __future__ import annotations

import contextlib
import fcntl
import os
import shutil
import subprocess
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from servoamp.board import REPO, Board, QemuError


@dataclass(frozen=True)
class Images:
    """Everything QEMU loads.

    On the Zynq-7000 (boot flow ``stub``): the boot stub (both variants)
    and the zImage. On the ZynqMP (``tf-a``): ``bl31`` (TF-A), ``stub`` is
    the BL33 stub and ``zimage`` the arm64 Image (:attr:`kernel`)."""

    stub: Path
    zimage: Path
    dtb: Path
    initramfs: Path
    firmware: tuple[Path, ...] = ()
    stub_icount: Path | None = None   # park loop in wfi + private timer, for -icount (stub.S)
    bl31: Path | None = None          # TF-A's BL31 (boot flow tf-a)

    @property
    def kernel(self) -> Path:
        """The kernel image: zImage (arm) or Image (arm64)."""
        return self.zimage


def _run(cmd: Sequence[str | Path], **kw: Any) -> subprocess.CompletedProcess[str]:
    res = subprocess.run([str(c) for c in cmd], text=True, capture_output=True, **kw)
    if res.returncode != 0:
        raise QemuError(
            f"command failed ({res.returncode}): {' '.join(map(str, cmd))}\n"
            f"{res.stdout[-3000:]}{res.stderr[-3000:]}"
        )
    return res


KERNELS = ("rt", "vanilla")


def default_kernel() -> str:
    """The kernel variant the board boots: ``rt`` (PREEMPT_RT, the
    default: issue 23's latency table, docs/cycle-rt.md) or ``vanilla`` (the
    non-preemptible 6.1), from $SERVOAMP_KERNEL (``west emu --kernel`` sets
    it); linux/kernel/build.sh --variant builds either."""
    kernel = os.environ.get("SERVOAMP_KERNEL") or "rt"
    if kernel not in KERNELS:
        raise QemuError(f"SERVOAMP_KERNEL={kernel}: expected one of {', '.join(KERNELS)}")
    return kernel


def kernel_link(kernel: str | None = None) -> Path:
    """``build/kernel-rt`` or ``build/kernel`` (vanilla): the link to the
    variant's cached build (linux/kernel/build.sh)."""
    kernel = kernel or default_kernel()
    return REPO / "build" / ("kernel" if kernel == "vanilla" else f"kernel-{kernel}")


def kernel_dir(kernel: str | None = None) -> Path:
    """The kernel build of variant ``kernel`` (default:
    :func:`default_kernel`; ``build/kernel-rt`` or ``build/kernel`` -> cache), built if
    its inputs have no cached build."""
    kernel = kernel or default_kernel()
    # always through the build script (0.1 s when its key is cached): a link
    # left in build/ by an older configuration would boot a stale kernel
    subprocess.run([REPO / "linux/kernel/build.sh", "--variant", kernel], check=True,
                   stdout=subprocess.DEVNULL)
    return kernel_link(kernel).resolve()


def kernel_source(kdir: Path) -> Path:
    for line in (kdir / "info").read_text().splitlines():
        if line.startswith("src="):
            return Path(line[4:])
    raise QemuError(f"{kdir}/info has no src=")


def build_stub(board: Board, park_wfe: bool = True) -> Path:
    """Assemble the boot stub with the board's addresses: ``stub.bin``
    (CPU1 parks in wfe, for the host clock) or, with ``park_wfe=False``,
    ``stub-icount.bin`` (CPU1 waits in wfi, woken by its private timer, for
    virtual time; see stub.S)."""
    out = board.build_dir
    park = board.addr("load", "park_loop") - board.addr("load", "boot_stub")
    name = "stub" if park_wfe else "stub-icount"
    _run(
        [
            "make", "-s", "-C", board.folder / "boot", f"OUT={out}", f"STUB={name}",
            f"PARK_WFE={int(park_wfe)}",
            f"STUB_ADDR={board.addr('load', 'boot_stub'):#x}",
            f"ZIMAGE_ADDR={board.addr('load', 'zimage'):#x}",
            f"DTB_ADDR={board.addr('load', 'dtb'):#x}",
            f"ARM_PLL_CTRL_VALUE={board.addr('slcr', 'arm_pll_ctrl'):#x}",
            f"PARK_OFFSET={park:#x}",
        ]
    )
    return out / f"{name}.bin"


def build_dtb(board: Board, ksrc: Path, initramfs: Path | None = None, out_dir: Path | None = None,
              dts_variant: str | None = None) -> Path:
    """cpp + dtc on the board's Linux DTS (warnings are errors), then put the
    initramfs location into /chosen. ``out_dir``: where the DTB goes
    (default: the board's build directory; a benchmark booting an initramfs
    of its own passes its own directory). ``dts_variant``: see
    :meth:`Board.dts`; the DTB is named after its source (linux.dtb,
    linux-nopmu.dtb).

    With an initramfs, the DTB returned is named after it too
    (``linux-<initramfs key>.dtb``): its /chosen holds that initramfs's
    size, and two boots prepared at once (pytest-xdist workers) with
    different firmware sets must not read each other's. ``linux.dtb`` is
    written as well, the latest one (devicetree/validate.sh reads it).
    Every file is written under a temporary name and renamed into place,
    so a reader never sees half of one."""
    out = out_dir or board.build_dir
    out.mkdir(parents=True, exist_ok=True)
    dts = board.dts(dts_variant)
    tmp = f".{os.getpid()}"
    pre = out / f"{dts.stem}.dts.pp{tmp}"
    work = out / f"{dts.stem}.dtb{tmp}"
    try:
        _run(
            [
                "cpp", "-nostdinc", "-undef", "-x", "assembler-with-cpp", "-D__DTS__",
                "-I", ksrc / "include", "-I", ksrc / f"arch/{board.arch}/boot/dts",
                "-I", REPO / "devicetree", "-o", pre, dts,
            ]
        )
        os.replace(pre, out / f"{dts.stem}.dts.pp")
        res = _run(["dtc", "-I", "dts", "-O", "dtb", "-o", work, out / f"{dts.stem}.dts.pp"])
        if res.stderr.strip():
            raise QemuError(f"dtc warnings on {dts}:\n{res.stderr}")
        dtb = out / f"{dts.stem}.dtb"
        if initramfs is not None:
            start = board.addr("load", "initramfs")
            end = start + initramfs.stat().st_size
            _run(["fdtput", "-t", "x", work, "/chosen", "linux,initrd-start", f"{start:x}"])
            _run(["fdtput", "-t", "x", work, "/chosen", "linux,initrd-end", f"{end:x}"])
            keyed = out / f"{dts.stem}-{initramfs.parent.name}.dtb"
            shutil.copyfile(work, f"{keyed}{tmp}")
            os.replace(f"{keyed}{tmp}", keyed)
            os.replace(work, dtb)
            return keyed
        os.replace(work, dtb)
        return dtb
    finally:
        for f in (pre, work):
            f.unlink(missing_ok=True)


# The out-of-tree modules a board can load (board.yaml linux.modules):
# linux/<folder>/ -> its module
KERNEL_MODULES = {"remoteproc": "zynq_servo_rproc.ko", "uio": "servoamp_cycle_uio.ko"}


def build_modules(kdir: Path, folders: Sequence[str] = tuple(KERNEL_MODULES)) -> list[Path]:
    """The out-of-tree modules of ``folders`` (default: every one; a
    board's are :attr:`Board.modules`) built against the kernel build
    ``kdir`` (linux/kmod.mk, which takes the architecture from the kernel's
    info file; about 1 s each)."""
    unknown = [f for f in folders if f not in KERNEL_MODULES]
    if unknown:
        raise QemuError(f"no kernel module folder {', '.join(unknown)} (have: {', '.join(KERNEL_MODULES)})")
    key = next(l[4:] for l in (kdir / "info").read_text().splitlines() if l.startswith("key="))
    out = []
    for folder in folders:
        build = REPO / "build/linux" / folder / key
        _run(["make", "-s", "-C", REPO / "linux" / folder, f"KDIR={kdir / 'obj'}", f"BUILD={build}"])
        out.append(build / KERNEL_MODULES[folder])
    return out


def _stage(src: Path, dst: Path) -> None:
    """Copy ``src`` to ``dst`` under a temporary name, then rename: a boot
    being prepared at the same time (another pytest-xdist worker) reads
    the old file or the new one, never half of one."""
    tmp = dst.with_name(f".{dst.name}.{os.getpid()}")
    shutil.copyfile(src, tmp)
    os.replace(tmp, dst)


def build_test_firmware(board: Board | None = None) -> list[Path]:
    """The board's test firmware (good and bad images): board.yaml's
    ``test_firmware`` (a fixtures folder with a Makefile, and make variables
    taken from the board file by key path); tests/robot/fixtures when the
    board names none. The board's ``servo.default_firmware`` image is staged
    a second time under the name the remoteproc driver loads by default."""
    spec: dict[str, Any] = dict(board.data.get("test_firmware", {})) if board else {}
    src = REPO / str(spec.get("dir", "tests/robot/fixtures"))
    out = REPO / "build/tests/fixtures" / (board.name if board and spec else "")
    make_vars = [f"{k}={board.addr(*str(path).split('.')):#x}"
                 for k, path in dict(spec.get("vars", {})).items()] if board else []
    _run(["make", "-s", "-C", src, f"OUT={out}", *make_vars])
    images = sorted(out.glob("*.elf"))
    default = board.servo.get("default_firmware") if board else None
    if default:
        staged = out / "default" / str(default["name"])
        staged.parent.mkdir(exist_ok=True)
        _stage(out / str(default["image"]), staged)
        images.append(staged)
    return images


# rpu_app's outputs (rpu_app/Makefile) and the names they get in the guest's
# /lib/firmware: "rpu_app*.elf" names the firmware, where "servo.elf" would not.
RPU_APP_IMAGES = {"servo.elf": "rpu_app.elf", "servo-norsc.elf": "rpu_app-norsc.elf"}
# rpu_app's builds for one board: name suffix -> the servo devicetree in
# boards/<board>/ ("": the board's own axes; "-can": its axes on CiA 402
# drives over CAN, staged as rpu_app-can.elf, built when the board has one)
RPU_APP_VARIANTS = {"": "servo.dts", "-can": "servo-can.dts"}


def rpu_app_firmware(board: Board, build: bool = True) -> list[Path]:
    """rpu_app's ELFs for ``board``, built with rpu_app's Makefile when it
    has one, staged under their /lib/firmware names. Empty when rpu_app
    has not been written yet."""
    mk = REPO / "rpu_app" / "Makefile"
    stage = REPO / "build" / "firmware" / board.name
    found = []
    for variant, dts in RPU_APP_VARIANTS.items():
        dts_path = REPO / "boards" / board.name / dts
        src_dir = REPO / "build" / "rpu_app" / (board.name + variant)
        if not dts_path.exists():
            continue
        if build and mk.exists():
            _run(["make", "-s", "-C", REPO / "rpu_app", "-j2", f"BOARD={board.name}",
                  f"DTS={dts_path}", f"BUILD={src_dir}"])
        for src, name in RPU_APP_IMAGES.items():
            if variant and src != "servo.elf":
                continue        # a variant's image with its resource table only
            if (src_dir / src).exists():
                staged = stage / name.replace("rpu_app", "rpu_app" + variant, 1)
                stage.mkdir(parents=True, exist_ok=True)
                _stage(src_dir / src, staged)
                found.append(staged)
    return found


# Linux's architecture (Board.arch, the kernel's name) -> the guest's Debian
# architecture: the initramfs' busybox and the rows of
# scripts/mk/guest-arch.mk (servod's and motion's builds)
DEBIAN_ARCH = {"arm": "armhf", "arm64": "arm64"}


def guest_arch(board: Board) -> str:
    """The board's userland architecture in Debian's terms (``armhf``,
    ``arm64``), from board.yaml's linux.arch."""
    try:
        return DEBIAN_ARCH[board.arch]
    except KeyError:
        raise QemuError(f"board {board.name}: linux.arch {board.arch!r} is none of {', '.join(DEBIAN_ARCH)}") from None


def build_userland(arch: str = "armhf") -> list[Path]:
    """servod and ampctl (linux/servod, static) for the Debian architecture
    ``arch`` (:func:`guest_arch`), when their sources exist:
    build/linux/servod (armhf) or build/linux/servod-<arch>, as
    linux/servod/Makefile names them."""
    mk = REPO / "linux" / "servod" / "Makefile"
    if not mk.exists():
        return []
    out = REPO / "build" / "linux" / ("servod" if arch == "armhf" else f"servod-{arch}")
    _run(["make", "-s", "-C", mk.parent, f"GUEST_ARCH={arch}", f"BUILD={out}"])
    return [out / "servod", out / "ampctl"]


def build_initramfs(modules: Sequence[Path], firmware: Sequence[Path], bins: Sequence[Path] = (),
                    arch: str = "armhf") -> Path:
    """linux/initramfs/build.sh (cached by its inputs) for the guest's
    Debian architecture: ``armhf`` (Zynq-7000) or ``arm64`` (ZynqMP)."""
    cmd: list[str | Path] = [REPO / "linux/initramfs/build.sh", "--print", "--arch", arch]
    for m in modules:
        cmd += ["--module", m]
    for f in firmware:
        cmd += ["--firmware", f]
    for b in bins:
        cmd += ["--bin", b]
    res = subprocess.run([str(c) for c in cmd], text=True, stdout=subprocess.PIPE, check=True)
    return Path(res.stdout.strip().splitlines()[-1])


def prepare_images(
    board: Board, firmware: Sequence[Path] | None = None, with_rpu_app: bool = True,
    dts_variant: str | None = None,
) -> Images:
    """Build (or take from the caches) every image of a boot.

    ``firmware``: ELF files for /lib/firmware; default: the board's test
    fixtures (:func:`build_test_firmware`) plus rpu_app's ELF(s) for the
    board (its servo devicetree picks the platform: the A9 or the R5).
    ``dts_variant``: see :meth:`Board.dts`.
    """
    with _images_lock():
        if firmware is None:
            firmware = build_test_firmware(board) + (rpu_app_firmware(board) if with_rpu_app else [])
        if board.boot_flow == "tf-a":
            return prepare_tf_a_images(board, firmware, dts_variant)
        return _prepare_stub_images(board, firmware, dts_variant)


@contextlib.contextmanager
def _images_lock() -> Iterator[None]:
    """One :func:`prepare_images` at a time on this tree (an flock on
    build/.images.lock): pytest-xdist workers, or a test and a demo, share
    build/ and the caches; the second waits for the first's builds and then
    finds them done."""
    lock = REPO / "build" / ".images.lock"
    lock.parent.mkdir(parents=True, exist_ok=True)
    with open(lock, "a") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


def _prepare_stub_images(board: Board, firmware: Sequence[Path], dts_variant: str | None) -> Images:
    """:func:`prepare_images` for the boot flow ``stub`` (the Zynq-7000)."""
    kdir = kernel_dir()
    modules = build_modules(kdir, board.modules)
    arch = guest_arch(board)
    initramfs = build_initramfs(modules, firmware, build_userland(arch), arch=arch)
    stub = build_stub(board)
    stub_icount = build_stub(board, park_wfe=False)
    dtb = build_dtb(board, kernel_source(kdir), initramfs, dts_variant=dts_variant)
    return Images(
        stub=stub, zimage=kdir / "zImage", dtb=dtb, initramfs=initramfs, firmware=tuple(firmware),
        stub_icount=stub_icount,
    )


# --------------------------------------------------------------------------
# The TF-A boot chain (ZynqMP): BL31, the BL33 stub, the arm64 kernel
# --------------------------------------------------------------------------


def board_kernel_dir(board: Board) -> Path:
    """The kernel of a board that names its own build (linux.build, e.g.
    linux/kernel/build-zynqmp.sh, and linux.link, the link it keeps to its
    cache directory), built if its inputs have no cached build."""
    link = REPO / str(board.linux["link"])
    # always through the build script (cached by its inputs: 0.1 s), so a
    # link left by an older config fragment is moved to the current build
    subprocess.run([REPO / str(board.linux["build"])], check=True, stdout=subprocess.DEVNULL)
    return link.resolve()


def build_tf_a(board: Board) -> Path:
    """TF-A's BL31 for the board (boot/tf-a/build.sh, cached by its
    inputs), built with the board's numbers: ZYNQMP_ATF_MEM_BASE/SIZE
    (tf_a.mem_base/mem_size) and PRELOADED_BL33_BASE (load.bl33). Returns
    bl31.bin; its entry must be load.tf_a, where CPU0 starts."""
    base = board.addr("tf_a", "mem_base")
    if base != board.addr("load", "tf_a"):
        raise QemuError(f"board {board.name}: load.tf_a {board.addr('load', 'tf_a'):#x} is not "
                        f"tf_a.mem_base {base:#x} (BL31 runs where it is linked)")
    res = _run([
        REPO / "boot/tf-a/build.sh", "--print",
        "--mem-base", f"{base:#x}", "--mem-size", f"{board.addr('tf_a', 'mem_size'):#x}",
        "--bl33", f"{board.addr('load', 'bl33'):#x}",
        "--console", str(board.data["tf_a"].get("console", "cadence0")),
    ])
    out = Path(res.stdout.strip().splitlines()[-1])
    info = dict(line.split("=", 1) for line in (out / "info").read_text().splitlines() if "=" in line)
    if int(info["entry"], 0) != base:
        raise QemuError(f"{out}/bl31.elf: entry {info['entry']}, expected {base:#x}")
    return out / "bl31.bin"


def build_bl33(board: Board) -> Path:
    """The BL33 stub (boards/<board>/boot/bl33.S): releases the RPU's bus
    and power-gate resets as the FSBL would (fsbl.rst_lpd_top,
    fsbl.rpu_release), then enters the Image at load.image with x0 =
    load.dtb."""
    out = board.build_dir
    _run([
        "make", "-s", "-C", board.folder / "boot", f"OUT={out}",
        f"BL33_ADDR={board.addr('load', 'bl33'):#x}",
        f"IMAGE_ADDR={board.addr('load', 'image'):#x}",
        f"DTB_ADDR={board.addr('load', 'dtb'):#x}",
        f"RST_LPD_TOP={board.addr('fsbl', 'rst_lpd_top'):#x}",
        f"RPU_RELEASE={board.addr('fsbl', 'rpu_release'):#x}",
    ])
    return out / "bl33.bin"


def prepare_tf_a_images(board: Board, firmware: Sequence[Path] = (), dts_variant: str | None = None) -> Images:
    """The images of a board booted by TF-A (boot flow ``tf-a``): BL31, the
    BL33 stub, the board's kernel (its own build script), the initramfs of
    the board's architecture (busybox, /init; servod and ampctl built for
    it; the board's modules built against its kernel in /lib/modules;
    ``firmware`` in /lib/firmware) and the DTB of ``dts_variant``."""
    kdir = board_kernel_dir(board)
    arch = guest_arch(board)
    initramfs = build_initramfs(build_modules(kdir, board.modules), firmware, build_userland(arch), arch=arch)
    dtb = build_dtb(board, kernel_source(kdir), initramfs, dts_variant=dts_variant)
    dtb_max = board.addr("load", "image") - board.addr("load", "dtb")
    if dtb.stat().st_size > dtb_max:
        raise QemuError(f"{dtb}: {dtb.stat().st_size} bytes, more than the {dtb_max} before the Image")
    image = kdir / str(board.linux.get("image", "Image"))
    image_max = board.addr("load", "initramfs") - board.addr("load", "image")
    if image.stat().st_size > image_max:
        raise QemuError(f"{image}: {image.stat().st_size} bytes, more than the {image_max} before the initramfs")
    return Images(
        stub=build_bl33(board), zimage=image, dtb=dtb,
        initramfs=initramfs, firmware=tuple(firmware), bl31=build_tf_a(board),
    )
