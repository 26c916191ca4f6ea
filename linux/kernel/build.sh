#!/usr/bin/env bash
# Build the servoamp Linux kernel for the Zynq-7000 (zImage + the prepared
# build tree that the out-of-tree remoteproc module is compiled against).
#
#   linux/kernel/build.sh            # build or reuse the cached kernel
#   linux/kernel/build.sh --print    # same, then print the kernel directory
#
# Source: Debian's linux-source-6.1 (/usr/src/linux-source-6.1.tar.xz,
# installed by scripts/bootstrap.sh). Configuration: `allnoconfig` plus
# servoamp.config through KCONFIG_ALLCONFIG; every symbol of the fragment is
# checked in the resulting .config.
#
# Cache: ${SERVOAMP_CACHE:-$HOME/.cache/servoamp}/
#   linux-src/<pkg-version>/linux-source-6.1/   extracted source (shared)
#   kernel/<key>/obj/                           O= build tree
#   kernel/<key>/zImage, config, info, ok       results (ok = complete)
# key = sha256(source package version, fragment, this script). A new key
# starts from the newest complete build tree of the same source version, so
# a one-symbol change rebuilds incrementally. build/kernel in the repository
# is a symlink to the current kernel/<key>/ directory.
#
# Only the SERVOAMP_KEEP (default 3) newest complete builds are kept.
#
# Environment: SERVOAMP_CACHE, SERVOAMP_JOBS (default 2), SERVOAMP_KEEP.
set -euo pipefail

here=$(cd "$(dirname "$0")" && pwd)
repo=$(cd "$here/../.." && pwd)
fragment=$here/servoamp.config
cache=${SERVOAMP_CACHE:-$HOME/.cache/servoamp}
jobs=${SERVOAMP_JOBS:-2}
tarball=/usr/src/linux-source-6.1.tar.xz
print_dir=0
[ "${1:-}" = --print ] && print_dir=1

log() { printf '[kernel] %s\n' "$*" >&2; }
die() { printf '[kernel] error: %s\n' "$*" >&2; exit 1; }

[ -r "$tarball" ] || die "$tarball missing: run scripts/bootstrap.sh"
command -v arm-linux-gnueabihf-gcc >/dev/null || die "arm-linux-gnueabihf-gcc missing: run scripts/bootstrap.sh"
version=$(dpkg-query -W -f='${Version}' linux-source-6.1)
key=$({
	printf 'linux-source-6.1 %s\n' "$version"
	sha256sum <"$fragment"
	sha256sum <"$0"
} | sha256sum | cut -c1-16)
out=$cache/kernel/$key
src=$cache/linux-src/$version/linux-source-6.1
t0=$(date +%s.%N)

elapsed() { echo "$(date +%s.%N) $t0" | awk '{ printf "%.1f", $1 - $2 }'; }

publish() {
	mkdir -p "$repo/build"
	ln -sfn "$out" "$repo/build/kernel"
	[ $print_dir -eq 1 ] && printf '%s\n' "$out"
	return 0
}

mkdir -p "$cache/kernel"
exec 9>"$cache/kernel/.lock"
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
	mv "$src.tmp/linux-source-6.1" "$src"
	rmdir "$src.tmp"
	touch "$src/.servoamp-extracted"
fi

# 2. Seed the build tree from the newest complete build of this source
#    version (incremental rebuild), or start clean.
mkdir -p "$out"
if [ ! -d "$out/obj" ]; then
	seed=""
	for d in $(ls -td "$cache"/kernel/*/ 2>/dev/null); do
		d=${d%/}
		[ "$d" != "$out" ] && [ -f "$d/ok" ] &&
			grep -qx "version=$version" "$d/info" 2>/dev/null && { seed=$d; break; }
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
	make -C "$src" O="$out/obj" ARCH=arm CROSS_COMPILE=arm-linux-gnueabihf- \
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
		log "fragment symbol not applied: $line (got: $(grep -E "^(# )?${line%%=*}[= ]" "$out/obj/.config" || echo absent))"
		bad=1
	}
done <"$fragment"
[ $bad -eq 0 ] || die "the configuration does not match servoamp.config"

# 4. Build zImage, Module.symvers (modules) and the headers/scripts that an
#    out-of-tree module needs (modules_prepare).
log "building zImage modules modules_prepare with -j$jobs (log: $out/build.log)"
# a progress line every 30 s: a clean build takes 3-7 minutes on two cores
(
	trap 'exit 0' TERM
	while sleep 30; do
		log "building: $(elapsed) s elapsed, $(grep -c '^  CC' "$out/build.log" 2>/dev/null) files compiled (log: $out/build.log)"
	done
) &
ticker=$!
rc=0
kmake -j"$jobs" zImage modules modules_prepare >"$out/build.log" 2>&1 || rc=$?
kill "$ticker" 2>/dev/null || true
wait "$ticker" 2>/dev/null || true
[ $rc -eq 0 ] || { tail -30 "$out/build.log" >&2; die "kernel build failed"; }
[ -f "$out/obj/Module.symvers" ] || die "Module.symvers missing after the build"

cp "$out/obj/arch/arm/boot/zImage" "$out/zImage"
cp "$out/obj/.config" "$out/config"
secs=$(elapsed)
{
	echo "version=$version"
	echo "key=$key"
	echo "src=$src"
	echo "build_seconds=$secs"
	echo "zimage_bytes=$(stat -c %s "$out/zImage")"
	echo "kernelrelease=$(kmake -s kernelrelease)"
} >"$out/info"
touch "$out/ok"
# 5. Prune: keep the newest complete builds (each is about 130 MB).
ls -td "$cache"/kernel/*/ | tail -n +$((${SERVOAMP_KEEP:-3} + 1)) | while read -r d; do
	[ "${d%/}" = "$out" ] || rm -rf "${d%/}"
done
log "built in $secs s: $out/zImage ($(stat -c %s "$out/zImage") bytes)"
publish
