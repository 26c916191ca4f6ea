#!/usr/bin/env bash
# Build the servoamp Linux kernel for the ZynqMP (board zynqmp_qemu): arm64
# Image with mainline PREEMPT_RT, plus the prepared build tree that an
# out-of-tree module is compiled against. The Zynq-7000's kernel is
# build.sh's; this is its sibling for the second board, with a cache of its
# own (so build.sh's cache keys and pruning are untouched).
#
#   linux/kernel/build-zynqmp.sh            # build or reuse the cached kernel
#   linux/kernel/build-zynqmp.sh --print    # same, then print the kernel directory
#
# Source: Debian's linux-source-6.12 (/usr/src/linux-source-6.12.tar.xz,
# installed by scripts/bootstrap.sh): 6.12 has PREEMPT_RT in mainline for
# arm64 and the upstream R5 remoteproc driver (xlnx_r5_remoteproc), so no
# patch series is applied. Configuration: `allnoconfig` plus zynqmp.config
# through KCONFIG_ALLCONFIG; every symbol of the fragment is checked in the
# resulting .config. Cross compiler: Debian's gcc-aarch64-linux-gnu.
#
# Cache: ${SERVOAMP_CACHE:-$HOME/.cache/servoamp}/
#   linux-src/<pkg-version>/linux-source-6.12/   extracted source (shared)
#   kernel-zynqmp/<key>/obj/                     O= build tree
#   kernel-zynqmp/<key>/Image, config, info, ok  results (ok = complete)
# key = sha256(source package version, fragment, recipe, arch). A new key
# starts from the newest complete build tree of the same source, so a
# one-symbol change rebuilds incrementally. build/kernel-zynqmp in the
# repository links to the current kernel-zynqmp/<key>/ directory. Only the
# SERVOAMP_KEEP (default 3) newest complete builds are kept.
#
# Environment: SERVOAMP_CACHE, SERVOAMP_JOBS (default 2), SERVOAMP_KEEP.
set -euo pipefail

here=$(cd "$(dirname "$0")" && pwd)
repo=$(cd "$here/../.." && pwd)
fragment=$here/zynqmp.config
cache=${SERVOAMP_CACHE:-$HOME/.cache/servoamp}
jobs=${SERVOAMP_JOBS:-2}
pkg=linux-source-6.12
tarball=/usr/src/$pkg.tar.xz
arch=arm64
cross=aarch64-linux-gnu-
print_dir=0
# The build recipe in the key: change it (to any new value) when an edit of
# the build steps below must rebuild every cached kernel.
recipe=zynqmp-1

log() { printf '[kernel-zynqmp] %s\n' "$*" >&2; }
die() { printf '[kernel-zynqmp] error: %s\n' "$*" >&2; exit 1; }

while [ $# -gt 0 ]; do
	case $1 in
	--print) print_dir=1; shift ;;
	*) die "unknown argument: $1 (usage: build-zynqmp.sh [--print])" ;;
	esac
done

[ -r "$tarball" ] || die "$tarball missing: run scripts/bootstrap.sh"
command -v "${cross}gcc" >/dev/null || die "${cross}gcc missing: run scripts/bootstrap.sh"
version=$(dpkg-query -W -f='${Version}' "$pkg")
t0=$(date +%s.%N)
elapsed() { echo "$(date +%s.%N) $t0" | awk '{ printf "%.1f", $1 - $2 }'; }

key=$({
	printf '%s %s\n' "$pkg" "$version"
	sha256sum <"$fragment"
	printf 'recipe %s\narch %s\n' "$recipe" "$arch"
} | sha256sum | cut -c1-16)
src=$cache/linux-src/$version/$pkg
root=$cache/kernel-zynqmp
out=$root/$key
link=$repo/build/kernel-zynqmp

publish() {
	mkdir -p "$repo/build"
	ln -sfn "$out" "$link"
	[ $print_dir -eq 1 ] && printf '%s\n' "$out"
	return 0
}

if [ -f "$out/ok" ]; then
	log "cached: $out ($(elapsed) s)"
	publish
	exit 0
fi

mkdir -p "$root"
exec 9>"$root/.lock"
flock 9
if [ -f "$out/ok" ]; then
	log "cached: $out ($(elapsed) s)"
	publish
	exit 0
fi

# 1. Extract the source once per package version.
if [ ! -f "$src/.servoamp-extracted" ]; then
	log "extracting $tarball ($version)"
	rm -rf "$src.tmp"
	mkdir -p "$src.tmp"
	tar -xJf "$tarball" -C "$src.tmp"
	rm -rf "$src"
	mkdir -p "$(dirname "$src")"
	mv "$src.tmp/$pkg" "$src"
	rm -rf "$src.tmp"
	touch "$src/.servoamp-extracted"
fi

# 2. Seed the build tree from the newest complete build of this source
#    (incremental rebuild), or start clean.
mkdir -p "$out"
if [ ! -d "$out/obj" ]; then
	seed=""
	for d in $(ls -td "$root"/*/ 2>/dev/null); do
		d=${d%/}
		[ "$d" != "$out" ] && [ -f "$d/ok" ] && grep -qxF "src=$src" "$d/info" 2>/dev/null && { seed=$d; break; }
	done
	if [ -n "$seed" ]; then
		log "seeding the build tree from $seed (incremental build)"
		cp -a "$seed/obj" "$out/obj.tmp"
		mv "$out/obj.tmp" "$out/obj"
	else
		mkdir -p "$out/obj"
	fi
fi

kmake() {
	make -C "$src" O="$out/obj" ARCH=$arch CROSS_COMPILE=$cross \
		KBUILD_BUILD_USER=servoamp KBUILD_BUILD_HOST=servoamp "$@"
}

# 3. Configure: allnoconfig + fragment, then check every symbol.
log "configuring (allnoconfig + $(basename "$fragment"))"
kmake -s KCONFIG_ALLCONFIG="$fragment" allnoconfig >"$out/config.log" 2>&1 ||
	{ tail -20 "$out/config.log" >&2; die "configuration failed"; }
bad=0
while IFS= read -r line; do
	case $line in CONFIG_*=*) ;; *) continue ;; esac
	grep -qxF "$line" "$out/obj/.config" || {
		log "$(basename "$fragment") symbol not applied: $line (got: $(grep -E "^(# )?${line%%=*}[= ]" "$out/obj/.config" || echo absent))"
		bad=1
	}
done <"$fragment"
[ $bad -eq 0 ] || die "the configuration does not match $(basename "$fragment")"

# 4. Build Image, Module.symvers and what an out-of-tree module needs.
log "building Image modules modules_prepare with -j$jobs (log: $out/build.log)"
(
	trap 'exit 0' TERM
	while sleep 30; do
		log "building: $(elapsed) s elapsed, $(grep -c '^  CC' "$out/build.log" 2>/dev/null) files compiled (log: $out/build.log)"
	done
) &
ticker=$!
rc=0
kmake -j"$jobs" Image modules modules_prepare >"$out/build.log" 2>&1 || rc=$?
kill "$ticker" 2>/dev/null || true
wait "$ticker" 2>/dev/null || true
[ $rc -eq 0 ] || { tail -30 "$out/build.log" >&2; die "kernel build failed"; }

cp "$out/obj/arch/$arch/boot/Image" "$out/Image"
cp "$out/obj/.config" "$out/config"
secs=$(elapsed)
{
	echo "version=$version"
	echo "key=$key"
	echo "src=$src"
	echo "arch=$arch"
	echo "build_seconds=$secs"
	echo "image_bytes=$(stat -c %s "$out/Image")"
	echo "kernelrelease=$(kmake -s kernelrelease)"
	echo "variant=rt"
} >"$out/info"
touch "$out/ok"

# 5. Prune: keep the newest complete builds.
ls -td "$root"/*/ | tail -n +$((${SERVOAMP_KEEP:-3} + 1)) | while read -r d; do
	d=${d%/}
	[ "$d" = "$out" ] || rm -rf "$d"
done
log "built in $secs s: $out/Image ($(stat -c %s "$out/Image") bytes)"
publish
