#!/usr/bin/env bash
# Build the servoamp Linux kernel for the Zynq-7000 (zImage + the prepared
# build tree that the out-of-tree remoteproc module is compiled against).
# The ZynqMP's kernel (arm64, 6.12) is build-zynqmp.sh's, in a cache of its
# own.
#
#   linux/kernel/build.sh                    # build or reuse the cached board kernel (rt)
#   linux/kernel/build.sh --print            # same, then print the kernel directory
#   linux/kernel/build.sh --variant vanilla  # the non-preemptible kernel (see below)
#
# Source: Debian's linux-source-6.1 (/usr/src/linux-source-6.1.tar.xz,
# installed by scripts/bootstrap.sh). Configuration: `allnoconfig` plus
# servoamp.config through KCONFIG_ALLCONFIG; every symbol of the fragment is
# checked in the resulting .config.
#
# Variants: `rt` (the board's kernel, this script's default) and `vanilla`
# (the kernel above, non-preemptible: the board's kernel before issue 23's
# latency table; SERVOAMP_KERNEL=vanilla boots it). `rt` is the same
# source with Debian's PREEMPT_RT series (debian/patches-rt of the `linux`
# source package) applied in series order, configured with servoamp.config
# then rt.config (rt-series.skip names the patches of the series left out,
# with the reason). The series comes from the newest `linux` source package
# the machine's Debian mirror serves: a PRIVATE apt configuration (own
# sources list with deb-src lines for the suites of the machine's sources
# minus the security one, own state and cache; the mirror URI read from
# /etc/apt, never written here) downloads only its debian.tar.xz
# (`apt-get source --diff-only`, about 2 MB). The series is cached, so later
# runs need no network; SERVOAMP_RT_REFRESH=1 asks the mirror again.
#
# Cache: ${SERVOAMP_CACHE:-$HOME/.cache/servoamp}/
#   linux-src/<pkg-version>/linux-source-6.1/   extracted source (shared)
#   linux-src/<pkg-version>-rt-<series>/...     the same, RT series applied
#   linux-rt/<debian-version>/patches-rt/       the RT series (series + patches)
#   kernel/<key>/obj/                           O= build tree
#   kernel/<key>/zImage, config, info, ok       results (ok = complete)
# key = sha256(source package version, fragment, build recipe) for the
# vanilla kernel, plus variant, RT series (Debian version, hash of the
# series and its patches) and rt.config for `rt`. A new key starts from the
# newest complete build tree of the same (patched) source, so a one-symbol
# change rebuilds incrementally. build/kernel (vanilla) and build/kernel-rt
# in the repository are symlinks to the current kernel/<key>/ directory.
#
# Only the SERVOAMP_KEEP (default 3) newest complete builds of each variant
# are kept.
#
# Environment: SERVOAMP_CACHE, SERVOAMP_JOBS (default 2), SERVOAMP_KEEP,
# SERVOAMP_RT_REFRESH.
set -euo pipefail

here=$(cd "$(dirname "$0")" && pwd)
repo=$(cd "$here/../.." && pwd)
fragment=$here/servoamp.config
rt_fragment=$here/rt.config
rt_skip=$here/rt-series.skip
cache=${SERVOAMP_CACHE:-$HOME/.cache/servoamp}
jobs=${SERVOAMP_JOBS:-2}
tarball=/usr/src/linux-source-6.1.tar.xz
print_dir=0
variant=rt
# The build recipe in the key: change it (to any new value) when an edit of
# the build steps below must rebuild every cached kernel. Its value is the
# sha256 this script had when the key hashed the script itself, so the
# vanilla kernel kept its key when the variants came.
recipe=a974c7da9b9eae39383713816ad522d6b958821a439dd5e5100ccb8464580e12

log() { printf '[kernel] %s\n' "$*" >&2; }
die() { printf '[kernel] error: %s\n' "$*" >&2; exit 1; }

while [ $# -gt 0 ]; do
	case $1 in
	--print) print_dir=1; shift ;;
	--variant) [ $# -ge 2 ] || die "--variant needs a name (vanilla, rt)"; variant=$2; shift 2 ;;
	--variant=*) variant=${1#--variant=}; shift ;;
	*) die "unknown argument: $1 (usage: build.sh [--variant vanilla|rt] [--print])" ;;
	esac
done
case $variant in
vanilla | rt) ;;
*) die "unknown variant '$variant' (vanilla, rt)" ;;
esac

[ -r "$tarball" ] || die "$tarball missing: run scripts/bootstrap.sh"
command -v arm-linux-gnueabihf-gcc >/dev/null || die "arm-linux-gnueabihf-gcc missing: run scripts/bootstrap.sh"
version=$(dpkg-query -W -f='${Version}' linux-source-6.1)
t0=$(date +%s.%N)

elapsed() { echo "$(date +%s.%N) $t0" | awk '{ printf "%.1f", $1 - $2 }'; }

# debian_suites: the suites of the machine's Debian apt sources, the
# security suite left out (its armhf index is broken on the mirror, and the
# kernel's source there would be newer than any RT series anyway).
debian_suites() {
	local f suites=""
	for f in /etc/apt/sources.list.d/*.sources; do
		[ -r "$f" ] || continue
		suites="$suites $(awk '/^Suites:/ { for (i = 2; i <= NF; i++) if ($i !~ /security/) print $i }' "$f")"
	done
	if [ -z "${suites// /}" ] && [ -r /etc/apt/sources.list ]; then
		suites=$(awk '$1 == "deb" && $0 !~ /security/ { print $3 }' /etc/apt/sources.list)
	fi
	suites=$(printf '%s\n' $suites | sort -u | paste -sd' ')
	[ -n "$suites" ] || return 1
	printf '%s\n' "$suites"
}

# rt_patches DIR: the patch names of DIR/series in order, without those
# that rt-series.skip names.
rt_patches() {
	local p
	grep -v -e '^#' -e '^[[:space:]]*$' "$1/series" | while read -r p _; do
		grep -qxF "$p" "$rt_skip" || printf '%s\n' "$p"
	done
}

# rt_series: make sure an RT patch series is in $cache/linux-rt and set
# rt_dir (its folder), rt_debver (the Debian version of the `linux` source
# package it comes from) and rt_hash (series file + patches, in order).
rt_series() {
	local root=$cache/linux-rt apt_root tmp mirror suites diff d
	mkdir -p "$root"
	exec 8>"$root/.lock"
	flock 8
	rt_dir=""
	if [ "${SERVOAMP_RT_REFRESH:-0}" != 1 ]; then
		for d in $(ls -d "$root"/*/ 2>/dev/null | sort -V -r); do
			[ -f "$d/ok" ] && { rt_dir=${d%/}; break; }
		done
	fi
	if [ -z "$rt_dir" ]; then
		. "$repo/scripts/lib/debian-mirror.sh"
		mirror=$(debian_mirror) || die "cannot find the Debian mirror in /etc/apt"
		suites=$(debian_suites) || die "cannot find the Debian suites in /etc/apt"
		tmp=$(mktemp -d "$root/fetch.XXXXXX")
		apt_root=$tmp/apt
		private_apt_setup "$apt_root"
		for s in $suites; do
			echo "deb-src $mirror $s main"
		done >"$apt_root/etc/sources.list"
		log "fetching the PREEMPT_RT series: deb-src lines for $suites (private apt configuration)"
		apt-get "${PRIVATE_APT_OPTS[@]}" -qq update ||
			die "apt-get update with the private deb-src configuration failed"
		# the candidate is the newest version these suites serve
		(cd "$tmp" && apt-get "${PRIVATE_APT_OPTS[@]}" -qq source --download-only --diff-only linux \
			>"$tmp/source.log" 2>&1) ||
			{ cat "$tmp/source.log" >&2; die "apt-get source --diff-only linux failed"; }
		diff=$(ls "$tmp"/linux_*.debian.tar.xz 2>/dev/null | head -1)
		[ -n "$diff" ] || die "no linux_*.debian.tar.xz downloaded (see $tmp/source.log)"
		rt_debver=$(basename "$diff" .debian.tar.xz)
		rt_debver=${rt_debver#linux_}
		tar -xJf "$diff" -C "$tmp" debian/patches-rt ||
			die "$(basename "$diff") has no debian/patches-rt"
		[ -s "$tmp/debian/patches-rt/series" ] || die "$(basename "$diff"): debian/patches-rt/series missing"
		rm -rf "${root:?}/$rt_debver"
		mkdir -p "$root/$rt_debver"
		mv "$tmp/debian/patches-rt" "$root/$rt_debver/patches-rt"
		echo "$rt_debver" >"$root/$rt_debver/debian-version"
		touch "$root/$rt_debver/ok"
		rm -rf "$tmp"
		rt_dir=$root/$rt_debver
		log "RT series of linux $rt_debver cached in $rt_dir"
	fi
	rt_debver=$(cat "$rt_dir/debian-version")
	rt_hash=$({
		cd "$rt_dir/patches-rt"
		sha256sum series
		rt_patches . | while read -r p; do
			sha256sum "$p"
		done
	} | sha256sum | cut -c1-16)
	flock -u 8
}

if [ "$variant" = rt ]; then
	command -v patch >/dev/null || die "patch missing (build-essential brings it): run scripts/bootstrap.sh"
	rt_series
	key=$({
		printf 'linux-source-6.1 %s\n' "$version"
		sha256sum <"$fragment"
		printf '%s  -\n' "$recipe"
		printf 'variant rt\npatches-rt linux %s %s\n' "$rt_debver" "$rt_hash"
		sha256sum <"$rt_fragment"
	} | sha256sum | cut -c1-16)
	src=$cache/linux-src/$version-rt-$rt_hash/linux-source-6.1
	link=$repo/build/kernel-rt
	fragments=("$fragment" "$rt_fragment")
else
	# unchanged from before the variants: the vanilla kernel's key
	key=$({
		printf 'linux-source-6.1 %s\n' "$version"
		sha256sum <"$fragment"
		printf '%s  -\n' "$recipe"
	} | sha256sum | cut -c1-16)
	src=$cache/linux-src/$version/linux-source-6.1
	link=$repo/build/kernel
	fragments=("$fragment")
fi
out=$cache/kernel/$key

publish() {
	mkdir -p "$repo/build"
	ln -sfn "$out" "$link"
	[ $print_dir -eq 1 ] && printf '%s\n' "$out"
	return 0
}

# a complete build needs no lock (ok is written last): a cached kernel is
# not held up by another variant's build
if [ -f "$out/ok" ]; then
	log "cached: $out ($(elapsed) s)"
	publish
	exit 0
fi

mkdir -p "$cache/kernel"
exec 9>"$cache/kernel/.lock"
flock 9

if [ -f "$out/ok" ]; then
	log "cached: $out ($(elapsed) s)"
	publish
	exit 0
fi

# 1. Extract the source once per package version (and RT series).
if [ ! -f "$src/.servoamp-extracted" ]; then
	log "extracting $tarball ($version)"
	rm -rf "$src.tmp"
	mkdir -p "$src.tmp"
	tar -xJf "$tarball" -C "$src.tmp"
	if [ "$variant" = rt ]; then
		log "applying the PREEMPT_RT series of linux $rt_debver ($rt_dir/patches-rt)"
		n=0
		while read -r p _; do
			n=$((n + 1))
			patch -d "$src.tmp/linux-source-6.1" -p1 --batch --forward --no-backup-if-mismatch \
				-i "$rt_dir/patches-rt/$p" >"$src.tmp/patch.log" 2>&1 || {
				tail -20 "$src.tmp/patch.log" >&2
				why="does not apply to linux-source-6.1 $version"
				grep -q 'previously applied' "$src.tmp/patch.log" &&
					why="$why (some of it is already there: a stable backport? then name it in rt-series.skip, with the reason)"
				die "RT patch $p (number $n of the series of linux $rt_debver) $why"
			}
		done < <(rt_patches "$rt_dir/patches-rt")
		log "applied $n patches ($(grep -v -e '^#' -e '^[[:space:]]*$' "$rt_dir/patches-rt/series" | wc -l) in the series; rt-series.skip leaves out the others)"
		printf '%s %s\n' "$rt_debver" "$rt_hash" >"$src.tmp/linux-source-6.1/.servoamp-rt-series"
	fi
	rm -rf "$src"
	mkdir -p "$(dirname "$src")"
	mv "$src.tmp/linux-source-6.1" "$src"
	rm -rf "$src.tmp"
	touch "$src/.servoamp-extracted"
fi

# 2. Seed the build tree from the newest complete build of this source
#    (same version, same RT series or none: incremental rebuild), or start
#    clean.
mkdir -p "$out"
echo "$variant" >"$out/variant"
if [ ! -d "$out/obj" ]; then
	seed=""
	for d in $(ls -td "$cache"/kernel/*/ 2>/dev/null); do
		d=${d%/}
		[ "$d" != "$out" ] && [ -f "$d/ok" ] &&
			grep -qx "version=$version" "$d/info" 2>/dev/null &&
			grep -qxF "src=$src" "$d/info" 2>/dev/null && { seed=$d; break; }
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

# 3. Configure: allnoconfig + fragment(s), then check every symbol.
allconfig=$fragment
if [ ${#fragments[@]} -gt 1 ]; then
	allconfig=$out/fragment.config
	cat "${fragments[@]}" >"$allconfig"
fi
log "configuring (allnoconfig + $(for f in "${fragments[@]}"; do basename "$f"; done | paste -sd+))"
kmake -s KCONFIG_ALLCONFIG="$allconfig" allnoconfig >"$out/config.log" 2>&1 ||
	{ tail -20 "$out/config.log" >&2; die "configuration failed"; }
if [ "$variant" = rt ] && ! grep -qx 'CONFIG_PREEMPT_RT=y' "$out/obj/.config"; then
	die "CONFIG_PREEMPT_RT=y did not stick (got: $(grep -E '^(# )?CONFIG_PREEMPT(_RT|_NONE|_VOLUNTARY)?[= ]' "$out/obj/.config" | paste -sd' ')): the RT series in $src does not make it selectable for ARM"
fi
bad=0
for f in "${fragments[@]}"; do
	while IFS= read -r line; do
		case $line in CONFIG_*=*) ;; *) continue ;; esac
		grep -qxF "$line" "$out/obj/.config" || {
			log "$(basename "$f") symbol not applied: $line (got: $(grep -E "^(# )?${line%%=*}[= ]" "$out/obj/.config" || echo absent))"
			bad=1
		}
	done <"$f"
done
[ $bad -eq 0 ] || die "the configuration does not match $(for f in "${fragments[@]}"; do basename "$f"; done | paste -sd' ')"
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
	echo "variant=$variant"
	[ "$variant" != rt ] || printf 'patches_rt=linux %s %s\n' "$rt_debver" "$rt_hash"
} >"$out/info"
touch "$out/ok"
# 5. Prune: keep the newest complete builds of this variant (each is about
#    130 MB); a build without a variant file, or with `default` (the
#    vanilla kernel's name before the RT kernel became the board's), is a
#    vanilla one.
ls -td "$cache"/kernel/*/ | while read -r d; do
	d=${d%/}
	v=vanilla
	[ -f "$d/variant" ] && v=$(cat "$d/variant")
	[ "$v" != default ] || v=vanilla
	if [ "$v" = "$variant" ]; then echo "$d"; fi
done | tail -n +$((${SERVOAMP_KEEP:-3} + 1)) | while read -r d; do
	[ "$d" = "$out" ] || rm -rf "$d"
done
log "built in $secs s: $out/zImage ($(stat -c %s "$out/zImage") bytes)"
publish
