#!/usr/bin/env bash
# Build the servoamp initramfs (gzip'ed newc cpio) for a guest: the
# Zynq-7000's (armhf, the default) or the ZynqMP's (--arch arm64).
#
#   linux/initramfs/build.sh [--arch armhf|arm64] [--module KO]... [--firmware FILE]... [--bin FILE]... [--print]
#
# Contents: Debian's busybox-static:<arch> as the whole userland, /init
# (init.sh: mounts proc, sys, devtmpfs, debugfs, loads the modules,
# runs a shell on the console ttyPS0), /usr/sbin/irqprio (irqprio.c: the
# SCHED_FIFO priority of an interrupt's thread under PREEMPT_RT, run by /init
# for the cycle interrupt), /usr/sbin/servoamp-net (net-up.sh:
# eth0 up with 10.0.2.15/24 for QEMU user networking, run on demand, e.g. by
# the recording tests before servod), every module given with --module (the
# remoteproc driver, the cycle interrupt's UIO driver) in /lib/modules/,
# every --firmware file in /lib/firmware/ (same name), and
# every --bin file (static programs of the guest's arch: servod, ampctl)
# in /usr/bin/, and
# the G-code examples of the repository (examples/*.nc) in
# /usr/share/servoamp/examples/ (`ampctl run /usr/share/servoamp/examples/...`).
#
# busybox-static:<arch> comes from the machine's own Debian mirror through a
# PRIVATE apt configuration (own sources list, state and cache directories;
# never `dpkg --add-architecture`). The mirror URI is read from
# /etc/apt/sources.list.d/*.sources, so no host name is written anywhere in
# the repository.
#
# The archive is built with the kernel's own gen_init_cpio (no root needed
# for /dev/console) and cached under
# ${SERVOAMP_CACHE:-$HOME/.cache/servoamp}/initramfs/<key>/ where key hashes
# every input (arch, busybox .deb, init.sh, this script, modules, firmware
# files). build/initramfs.cpio.gz (armhf) or build/initramfs-arm64.cpio.gz
# links to the current one.
set -euo pipefail

here=$(cd "$(dirname "$0")" && pwd)
repo=$(cd "$here/../.." && pwd)
cache=${SERVOAMP_CACHE:-$HOME/.cache/servoamp}
modules=()
firmware=()
bins=()
print=0
arch=armhf

log() { printf '[initramfs] %s\n' "$*" >&2; }
die() { printf '[initramfs] error: %s\n' "$*" >&2; exit 1; }

while [ $# -gt 0 ]; do
	case $1 in
	--module) modules+=("$(realpath "$2")"); shift 2 ;;
	--firmware) firmware+=("$(realpath "$2")"); shift 2 ;;
	--bin) bins+=("$(realpath "$2")"); shift 2 ;;
	--print) print=1; shift ;;
	--arch) arch=$2; shift 2 ;;
	*) die "unknown argument: $1" ;;
	esac
done
# the guest's C compiler (irqprio) and where the image is linked from build/
case $arch in
armhf) cc=arm-linux-gnueabihf-gcc; link=initramfs.cpio.gz ;;
arm64) cc=aarch64-linux-gnu-gcc; link=initramfs-arm64.cpio.gz ;;
*) die "unknown --arch '$arch' (armhf, arm64)" ;;
esac
command -v "$cc" >/dev/null || die "$cc missing: run scripts/bootstrap.sh"
for f in "${modules[@]}"; do [ -f "$f" ] || die "module $f not found"; done
for f in "${firmware[@]}"; do [ -f "$f" ] || die "firmware $f not found"; done
for f in "${bins[@]}"; do [ -f "$f" ] || die "program $f not found"; done
examples=()
for f in "$repo"/examples/*.nc; do [ -f "$f" ] && examples+=("$f"); done

# the kernel's host tool: the same program in every kernel's tree (either
# board's)
gen_init_cpio=""
for k in kernel kernel-rt kernel-zynqmp; do
	[ -x "$repo/build/$k/obj/usr/gen_init_cpio" ] && { gen_init_cpio=$repo/build/$k/obj/usr/gen_init_cpio; break; }
done
[ -n "$gen_init_cpio" ] || die "build/kernel/obj/usr/gen_init_cpio missing: run linux/kernel/build.sh first"

. "$repo/scripts/lib/debian-mirror.sh"

# 1. busybox-static:<arch>, downloaded once per arch.
bbdir=$cache/initramfs/busybox
mkdir -p "$bbdir"
exec 9>"$bbdir/.lock"
flock 9
deb=$(ls "$bbdir"/busybox-static_*_"$arch".deb 2>/dev/null | tail -1 || true)
if [ -z "$deb" ]; then
	apt_root=$bbdir/apt-$arch
	private_apt_setup "$apt_root" -o "APT::Architecture=$arch" -o "APT::Architectures::=$arch"
	mirror=$(debian_mirror) || die "cannot find the Debian mirror in /etc/apt"
	echo "deb [arch=$arch] $mirror bookworm main" >"$apt_root/etc/sources.list"
	log "downloading busybox-static:$arch with a private apt configuration"
	apt-get "${PRIVATE_APT_OPTS[@]}" -qq update
	(cd "$bbdir" && apt-get "${PRIVATE_APT_OPTS[@]}" -qq download "busybox-static:$arch")
	deb=$(ls "$bbdir"/busybox-static_*_"$arch".deb | tail -1)
	rm -rf "$apt_root"
fi
flock -u 9

# 2. Cache key over every input.
key=$({
	printf 'arch %s\n' "$arch"
	sha256sum "$deb" "$here/init.sh" "$here/net-up.sh" "$here/irqprio.c" "$0" | cut -d' ' -f1
	for f in "${modules[@]}"; do printf '%s %s\n' "$(sha256sum <"$f")" "$(basename "$f")"; done
	for f in "${firmware[@]}"; do printf '%s %s\n' "$(sha256sum <"$f")" "$(basename "$f")"; done
	for f in "${bins[@]}"; do printf 'bin %s %s\n' "$(sha256sum <"$f")" "$(basename "$f")"; done
	for f in "${examples[@]}"; do printf 'example %s %s\n' "$(sha256sum <"$f")" "$(basename "$f")"; done
} | sha256sum | cut -c1-16)
out=$cache/initramfs/$key
image=$out/initramfs.cpio.gz

publish() {
	mkdir -p "$repo/build"
	ln -sfn "$image" "$repo/build/$link"
	[ $print -eq 0 ] || printf '%s\n' "$image"
	return 0
}

if [ -f "$image" ]; then
	log "cached: $image"
	publish
	exit 0
fi

# 3. Staging tree and gen_init_cpio list.
stage=$(mktemp -d)
trap 'rm -rf "$stage"' EXIT
dpkg-deb -x "$deb" "$stage/deb"
bb=$stage/deb/bin/busybox
[ -f "$bb" ] || die "no bin/busybox in $deb"
# irqprio (the interrupt thread's priority under PREEMPT_RT; busybox has no
# chrt), a static program like servod
"$cc" -static -O2 -Wall -Wextra -Werror -o "$stage/irqprio" "$here/irqprio.c" ||
	die "irqprio.c does not build"
list=$stage/list
{
	for d in /bin /sbin /dev /proc /sys /tmp /root /etc /lib /lib/modules \
		/lib/firmware /usr /usr/bin /usr/sbin /usr/share /usr/share/servoamp \
		/usr/share/servoamp/examples /var /run; do
		echo "dir $d 755 0 0"
	done
	echo "nod /dev/console 600 0 0 c 5 1"
	echo "nod /dev/null 666 0 0 c 1 3"
	echo "file /bin/busybox $bb 755 0 0"
	echo "slink /bin/sh busybox 777 0 0"
	echo "file /init $here/init.sh 755 0 0"
	echo "file /usr/sbin/servoamp-net $here/net-up.sh 755 0 0"
	echo "file /usr/sbin/irqprio $stage/irqprio 755 0 0"
	for f in "${modules[@]}"; do
		echo "file /lib/modules/$(basename "$f") $f 644 0 0"
	done
	for f in "${firmware[@]}"; do
		echo "file /lib/firmware/$(basename "$f") $f 644 0 0"
	done
	for f in "${bins[@]}"; do
		echo "file /usr/bin/$(basename "$f") $f 755 0 0"
	done
	for f in "${examples[@]}"; do
		echo "file /usr/share/servoamp/examples/$(basename "$f") $f 644 0 0"
	done
} >"$list"

mkdir -p "$out"
"$gen_init_cpio" "$list" | gzip -9n >"$image.tmp"
mv "$image.tmp" "$image"
cp "$list" "$out/list"
log "built $image ($(stat -c %s "$image") bytes, busybox $(basename "$deb"))"
publish
