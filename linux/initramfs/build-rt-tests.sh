#!/usr/bin/env bash
# Build the rt-tests overlay (a gzip'ed newc cpio) for a guest architecture
# (armhf: the Zynq-7000's A9, the default; arm64: the ZynqMP's A53):
# cyclictest and hackbench with the glibc they link, for the latency
# benchmark only (bench/cycle/rt_latency_bench.py; issues 23, 35). The board's own
# initramfs (build.sh) is not changed: the benchmark concatenates this
# archive to it (Linux unpacks concatenated cpio archives in order) into an
# image of its own.
#
#   linux/initramfs/build-rt-tests.sh [--arch armhf|arm64] [--print]
#
# Contents: /usr/bin/cyclictest and /usr/bin/hackbench from Debian's
# rt-tests:<arch>, libnuma1:<arch>, and libc6:<arch>'s libraries and loader
# (/lib/ld-linux-armhf.so.3, /lib/ld-linux-aarch64.so.1), with no
# /etc/ld.so.conf: the programs run with the loader's built-in multiarch
# directories (/lib/<triplet>, /usr/lib/<triplet>).
#
# The debs come from the machine's own Debian mirror through a PRIVATE apt
# configuration, exactly as build.sh fetches busybox-static (own sources
# list, state and cache directories; never `dpkg --add-architecture`; the
# mirror URI read from /etc/apt, no host name in the repository; no security
# suite: its armhf index is broken on the mirror). Cached under
# ${SERVOAMP_CACHE:-$HOME/.cache/servoamp}/initramfs/rt-tests/<key>/ where
# key hashes the debs (of the one architecture) and this script. --print
# prints the archive's path.
set -euo pipefail

here=$(cd "$(dirname "$0")" && pwd)
repo=$(cd "$here/../.." && pwd)
cache=${SERVOAMP_CACHE:-$HOME/.cache/servoamp}
print=0
arch=armhf
pkgs=(rt-tests libnuma1 libc6 libgcc-s1)

log() { printf '[rt-tests] %s\n' "$*" >&2; }
die() { printf '[rt-tests] error: %s\n' "$*" >&2; exit 1; }

while [ $# -gt 0 ]; do
	case $1 in
	--print) print=1; shift ;;
	--arch) [ $# -ge 2 ] || die "--arch needs a value"; arch=$2; shift 2 ;;
	*) die "unknown argument: $1" ;;
	esac
done
# the dynamic loader each architecture's libc6 ships
case $arch in
armhf) loader=lib/ld-linux-armhf.so.3 ;;
arm64) loader=lib/ld-linux-aarch64.so.1 ;;
*) die "--arch $arch: armhf or arm64" ;;
esac

. "$repo/scripts/lib/debian-mirror.sh"

# 1. The debs of the architecture, downloaded once (their names carry it).
debdir=$cache/initramfs/rt-tests/debs
mkdir -p "$debdir"
exec 9>"$debdir/.lock"
flock 9
missing=0
for p in "${pkgs[@]}"; do
	ls "$debdir/${p}"_*_"$arch".deb >/dev/null 2>&1 || missing=1
done
if [ $missing -eq 1 ]; then
	apt_root=$debdir/apt
	private_apt_setup "$apt_root" -o "APT::Architecture=$arch" -o "APT::Architectures::=$arch"
	mirror=$(debian_mirror) || die "cannot find the Debian mirror in /etc/apt"
	echo "deb [arch=$arch] $mirror bookworm main" >"$apt_root/etc/sources.list"
	log "downloading ${pkgs[*]} ($arch) with a private apt configuration"
	apt-get "${PRIVATE_APT_OPTS[@]}" -qq update
	(cd "$debdir" && apt-get "${PRIVATE_APT_OPTS[@]}" -qq download "${pkgs[@]/%/:$arch}")
	rm -rf "$apt_root"
fi
flock -u 9
debs=()
for p in "${pkgs[@]}"; do
	d=$(ls "$debdir/${p}"_*_"$arch".deb 2>/dev/null | tail -1 || true)
	[ -n "$d" ] || die "no ${p}_*_${arch}.deb in $debdir"
	debs+=("$d")
done

# 2. Cache key over every input.
key=$({ sha256sum "${debs[@]}" "$0" | cut -d' ' -f1; } | sha256sum | cut -c1-16)
out=$cache/initramfs/rt-tests/$key
image=$out/rt-tests.cpio.gz
if [ -f "$image" ]; then
	log "cached: $image"
	[ $print -eq 0 ] || printf '%s\n' "$image"
	exit 0
fi

# 3. Staging tree: the two programs, every shared library of the debs, the
#    loader; then one newc archive owned by root.
stage=$(mktemp -d)
trap 'rm -rf "$stage"' EXIT
for d in "${debs[@]}"; do dpkg-deb -x "$d" "$stage/x"; done
root=$stage/root
mkdir -p "$root/usr/bin"
for p in cyclictest hackbench; do
	cp -a "$stage/x/usr/bin/$p" "$root/usr/bin/$p" || die "no usr/bin/$p in rt-tests"
done
# the libraries (bookworm's libc6 ships them under /lib/<triplet>, libnuma1
# under /usr/lib/<triplet>), symlinks kept; gconv, locales, docs left out
(cd "$stage/x" && find lib usr/lib -maxdepth 2 \( -name '*.so*' \) \( -type f -o -type l \) 2>/dev/null) |
	while read -r f; do
		mkdir -p "$root/$(dirname "$f")"
		cp -a "$stage/x/$f" "$root/$f"
	done
ld=$(cd "$stage/x" && ls "$loader" 2>/dev/null || true)
[ -n "$ld" ] || die "no $loader in libc6:$arch"
mkdir -p "$out"
(cd "$root" && find . -mindepth 1 | sed 's|^\./||' | LC_ALL=C sort |
	cpio -o -H newc --owner=0:0 --reproducible --quiet) | gzip -9n >"$image.tmp"
mv "$image.tmp" "$image"
(cd "$root" && find . -mindepth 1 | sed 's|^\./||' | LC_ALL=C sort) >"$out/list"
log "built $image ($(stat -c %s "$image") bytes: $(cd "$debdir" && basename -a "${debs[@]}" | tr '\n' ' '))"
[ $print -eq 0 ] || printf '%s\n' "$image"
