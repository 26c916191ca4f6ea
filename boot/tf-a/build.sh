#!/usr/bin/env bash
# Build TF-A's BL31 for the ZynqMP (PLAT=zynqmp) from Debian's
# arm-trusted-firmware source package, cached by its inputs.
#
#   boot/tf-a/build.sh --mem-base 0x10000 --mem-size 0x40000 --bl33 0x80000 [--print]
#
# The numbers come from the board (boards/zynqmp_qemu/board.yaml, tf_a:
# python/servoamp/images passes them): --mem-base/--mem-size are
# ZYNQMP_ATF_MEM_BASE/SIZE (where BL31 runs; in DDR, so that OCM stays free
# for amp_lib and the R5's high vectors), --bl33 is PRELOADED_BL33_BASE
# (where BL31 enters the non-secure world at EL2 when no FSBL hand-off
# structure exists: QEMU has no boot ROM, so the boot mode reads JTAG and
# BL31 takes its build-time defaults). --console names TF-A's console
# (ZYNQMP_CONSOLE, default cadence0 = UART0); --debug builds DEBUG=1.
#
# With BL31 in DDR below 2 GiB, TF-A 2.8 also edits the devicetree it finds
# at 0x100000 (XILINX_OF_BOARD_DTB_ADDR): it adds the PSCI node and a
# reserved-memory node for itself. It passes nothing in x0 to BL33, so the
# board's BL33 is a stub (boards/zynqmp_qemu/boot) that does what U-Boot
# would: enter Linux with x0 = the DTB.
#
# Source: Debian's `arm-trusted-firmware` source package of bookworm (2.8),
# fetched once with a PRIVATE apt configuration
# (own deb-src list, state and cache; the mirror URI read from /etc/apt by
# scripts/lib/debian-mirror.sh, never written here) and unpacked with
# dpkg-source (Debian's patches applied). Flags as Debian's own rules:
# CFLAGS=--param=min-pagesize=0 TF_LDFLAGS=--no-warn-rwx-segments.
#
# Cache: ${SERVOAMP_CACHE:-$HOME/.cache/servoamp}/
#   tf-a-src/<version>/            the .dsc, tarballs and the unpacked tree
#   tf-a/<key>/bl31.elf, bl31.bin, info, ok
# key = sha256(package version and .dsc hash, build options, recipe). Only
# the SERVOAMP_KEEP (default 3) newest builds are kept.
set -euo pipefail

here=$(cd "$(dirname "$0")" && pwd)
repo=$(cd "$here/../.." && pwd)
cache=${SERVOAMP_CACHE:-$HOME/.cache/servoamp}
jobs=${SERVOAMP_JOBS:-2}
pkg=arm-trusted-firmware
cross=aarch64-linux-gnu-
recipe=tf-a-1
mem_base="" mem_size="" bl33="" console=cadence0 debug=0 print=0

log() { printf '[tf-a] %s\n' "$*" >&2; }
die() { printf '[tf-a] error: %s\n' "$*" >&2; exit 1; }

while [ $# -gt 0 ]; do
	case $1 in
	--mem-base) mem_base=$2; shift 2 ;;
	--mem-size) mem_size=$2; shift 2 ;;
	--bl33) bl33=$2; shift 2 ;;
	--console) console=$2; shift 2 ;;
	--debug) debug=1; shift ;;
	--print) print=1; shift ;;
	*) die "unknown argument: $1 (usage: build.sh --mem-base A --mem-size S --bl33 A [--console C] [--debug] [--print])" ;;
	esac
done
for v in mem_base mem_size bl33; do
	val=${!v}
	[[ $val =~ ^0x[0-9a-fA-F]+$ ]] || die "--${v//_/-} needs a hexadecimal address (got '${val}')"
done
command -v "${cross}gcc" >/dev/null || die "${cross}gcc missing: run scripts/bootstrap.sh"
command -v dpkg-source >/dev/null || die "dpkg-source missing (dpkg-dev): run scripts/bootstrap.sh"
t0=$(date +%s.%N)
elapsed() { echo "$(date +%s.%N) $t0" | awk '{ printf "%.1f", $1 - $2 }'; }

# 1. The source package, fetched once (bookworm's; the newest one cached is
#    used, and its version and .dsc hash are in the key).
srcroot=$cache/tf-a-src
mkdir -p "$srcroot"
exec 8>"$srcroot/.lock"
flock 8
srcdir=""
for d in $(ls -d "$srcroot"/*/ 2>/dev/null | sort -V -r); do
	[ -f "$d/ok" ] && { srcdir=${d%/}; break; }
done
if [ -z "$srcdir" ]; then
	. "$repo/scripts/lib/debian-mirror.sh"
	mirror=$(debian_mirror) || die "cannot find the Debian mirror in /etc/apt"
	tmp=$(mktemp -d "$srcroot/fetch.XXXXXX")
	private_apt_setup "$tmp/apt"
	echo "deb-src $mirror bookworm main" >"$tmp/apt/etc/sources.list"
	log "fetching the $pkg source package (private apt configuration)"
	apt-get "${PRIVATE_APT_OPTS[@]}" -qq update || die "apt-get update with the private deb-src list failed"
	(cd "$tmp" && apt-get "${PRIVATE_APT_OPTS[@]}" -qq source --download-only "$pkg" >"$tmp/source.log" 2>&1) ||
		{ cat "$tmp/source.log" >&2; die "apt-get source --download-only $pkg failed"; }
	dsc=$(ls "$tmp"/${pkg}_*.dsc 2>/dev/null | head -1)
	[ -n "$dsc" ] || die "no ${pkg}_*.dsc downloaded (see $tmp/source.log)"
	version=$(basename "$dsc" .dsc)
	version=${version#${pkg}_}
	(cd "$tmp" && dpkg-source -x "$(basename "$dsc")" src >"$tmp/unpack.log" 2>&1) ||
		{ cat "$tmp/unpack.log" >&2; die "dpkg-source -x $(basename "$dsc") failed"; }
	rm -rf "$tmp/apt" "${srcroot:?}/$version"
	echo "$version" >"$tmp/version"
	sha256sum <"$dsc" | cut -d' ' -f1 >"$tmp/dsc.sha256"
	touch "$tmp/ok"
	mv "$tmp" "$srcroot/$version"
	srcdir=$srcroot/$version
	log "$pkg $version unpacked in $srcdir/src"
fi
flock -u 8
version=$(cat "$srcdir/version")

opts=(PLAT=zynqmp RESET_TO_BL31=1 "DEBUG=$debug" "ZYNQMP_CONSOLE=$console"
	"ZYNQMP_ATF_MEM_BASE=$mem_base" "ZYNQMP_ATF_MEM_SIZE=$mem_size" "PRELOADED_BL33_BASE=$bl33")
key=$({
	printf '%s %s %s\n' "$pkg" "$version" "$(cat "$srcdir/dsc.sha256")"
	printf '%s\n' "${opts[@]}"
	printf 'recipe %s\n' "$recipe"
} | sha256sum | cut -c1-16)
out=$cache/tf-a/$key

publish() {
	mkdir -p "$repo/build"
	ln -sfn "$out" "$repo/build/tf-a"
	[ $print -eq 0 ] || printf '%s\n' "$out"
	return 0
}
if [ -f "$out/ok" ]; then
	log "cached: $out ($(elapsed) s)"
	publish
	exit 0
fi

# 2. Build out of tree (BUILD_BASE), so the unpacked source stays clean.
mkdir -p "$cache/tf-a"
exec 9>"$cache/tf-a/.lock"
flock 9
rm -rf "$out"
mkdir -p "$out"
log "building bl31 (${opts[*]}) -j$jobs (log: $out/build.log)"
rc=0
# Debian's flags go in the environment (as its rules pass them), so that
# TF-A's own CFLAGS/LDFLAGS (--gc-sections) are appended to, not replaced.
env CFLAGS=--param=min-pagesize=0 LDFLAGS= TF_LDFLAGS=--no-warn-rwx-segments \
	make -C "$srcdir/src" -j"$jobs" CROSS_COMPILE=$cross BUILD_BASE="$out/obj" \
	"${opts[@]}" bl31 >"$out/build.log" 2>&1 || rc=$?
[ $rc -eq 0 ] || { tail -30 "$out/build.log" >&2; die "bl31 build failed"; }
btype=release
[ "$debug" = 0 ] || btype=debug
cp "$out/obj/zynqmp/$btype/bl31/bl31.elf" "$out/bl31.elf"
cp "$out/obj/zynqmp/$btype/bl31.bin" "$out/bl31.bin"
entry=$(${cross}readelf -h "$out/bl31.elf" | awk '/Entry point/ { print $4 }')
[ $((entry)) -eq $((mem_base)) ] || die "bl31's entry $entry is not ZYNQMP_ATF_MEM_BASE $mem_base"
end=$((mem_base + $(stat -c %s "$out/bl31.bin")))
[ $end -le $((mem_base + mem_size)) ] || die "bl31.bin ends at $(printf '%#x' $end), past the region's end"
secs=$(elapsed)
{
	echo "version=$version"
	echo "key=$key"
	echo "entry=$entry"
	echo "bin_bytes=$(stat -c %s "$out/bl31.bin")"
	echo "build_seconds=$secs"
	printf 'option=%s\n' "${opts[@]}"
} >"$out/info"
rm -rf "$out/obj"
touch "$out/ok"
ls -td "$cache"/tf-a/*/ | tail -n +$((${SERVOAMP_KEEP:-3} + 1)) | while read -r d; do
	d=${d%/}
	[ "$d" = "$out" ] || rm -rf "$d"
done
log "built in $secs s: $out/bl31.bin ($(stat -c %s "$out/bl31.bin") bytes, entry $entry)"
publish
