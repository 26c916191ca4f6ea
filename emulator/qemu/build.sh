#!/usr/bin/env bash
# Build servoamp's own qemu-system-aarch64 10.0.2
# (Debian's source, with the patches in patches/: a Cadence TTC fix so the
# Zynq-7000 board runs under -icount without livelocking, the ZynqMP's RPU,
# and the other fixes and features README.md lists, with their qtests).
# One emulator for both boards: qemu-system-aarch64 has every Arm machine,
# the Zynq-7000 (xilinx-zynq-a9) as well as the ZynqMP (xlnx-zcu102).
#
#   emulator/qemu/build.sh            # build or reuse the cached QEMU
#   emulator/qemu/build.sh --print    # same, then print the install directory
#
# Use: PATH="$(emulator/qemu/build.sh --print)/bin:$PATH"
#
# Source: the upstream tarball Debian ships as qemu_10.0.2+ds.orig.tar.xz
# (bookworm-backports). It is located with `apt-get source --print-uris`
# through a private APT configuration (its own deb-src list, lists and cache
# under the cache directory; the system's apt configuration is not touched)
# and fetched with apt's own downloader, which checks its SHA256. The mirror
# is the one this machine's apt already uses (scripts/lib/debian-mirror.sh).
# The .dsc and .debian.tar.xz are not needed (and may answer 404).
#
# Cache: ${SERVOAMP_CACHE:-$HOME/.cache/servoamp}/
#   qemu-src/qemu_10.0.2+ds.orig.tar.xz   downloaded once (shared)
#   qemu-src/apt/                         the private APT state
#   qemu/<key>/bin/qemu-system-aarch64    the install (prefix)
#   qemu/<key>/libexec/servoamp/          the qtest binaries (TTC, CAN, canlink,
#                                         ZynqMP RPU, the ZCU102's PL timer,
#                                         upstream's xlnx-can-test)
#   qemu/<key>/info, build.log, ok        results (ok = complete, the
#                                         qtests passed)
#   qemu/<key>/src, build                 patched source and build tree, removed
#                                         after a successful build unless
#                                         SERVOAMP_QEMU_KEEP_BUILD=1
# key = sha256(tarball name and SHA256, every patch, the configure options,
# this script), 16 hex digits.
#
# Build dependencies come from Debian and are installed when missing
# (meson >= 1.5 and python3-pycotap from bookworm-backports, which
# scripts/bootstrap.sh adds to the system's apt sources).
#
# Environment: SERVOAMP_CACHE, SERVOAMP_JOBS (default 2), SERVOAMP_KEEP
# (complete builds kept, default 2), SERVOAMP_QEMU_KEEP_BUILD.
set -euo pipefail

here=$(cd "$(dirname "$0")" && pwd)
repo=$(cd "$here/../.." && pwd)
cache=${SERVOAMP_CACHE:-$HOME/.cache/servoamp}
jobs=${SERVOAMP_JOBS:-2}
print_dir=0
[ "${1:-}" = --print ] && print_dir=1

version=10.0.2
orig=qemu_${version}+ds.orig.tar.xz
orig_sha256=0901da33844a331bf8b3602b9c1fbd178e60b737c8e3ade678255bd090c9b9f1
suite=bookworm-backports
# Debian's python3 (not whatever python3 is first on PATH): configure's venv
# must see Debian's meson and pycotap in its system site-packages.
python=/usr/bin/python3

# configure options (the prefix is added below; it depends on the key)
config_opts=(
	--target-list=aarch64-softmmu
	--python=$python
	--disable-download
	--without-default-features
	--enable-slirp
	--enable-fdt=system
	--enable-pixman
	--disable-install-blobs
	--disable-debug-info
	--disable-docs
	--disable-tools
	--disable-guest-agent
	--disable-user
)
# ninja targets: the emulators, what `meson install` needs, our qtests
# (run-regression-test.sh knows which emulator each qtest runs on)
qtests=(cadence-ttc-test zynq-can-test can-lockstep-test xlnx-zynqmp-rpu-test
	xlnx-zcu102-pl-timer-test xlnx-can-test)
targets=(qemu-system-aarch64 trace/trace-events-all "${qtests[@]/#/tests/qtest/}")

log() { printf '[qemu] %s\n' "$*" >&2; }
die() { printf '[qemu] error: %s\n' "$*" >&2; exit 1; }

t0=$(date +%s.%N)
elapsed() { echo "$(date +%s.%N) $t0" | awk '{ printf "%.1f", $1 - $2 }'; }

# 1. Build dependencies (Debian packages; the -dev packages also bring the
#    libraries the emulators run with), installed only when missing.
need_pkgs=(gcc pkg-config ninja-build python3-venv libglib2.0-dev
	libpixman-1-dev libslirp-dev zlib1g-dev libfdt-dev xz-utils bzip2 patch)
installed() { [ "$(dpkg-query -W -f='${db:Status-Status}' "$1" 2>/dev/null)" = installed ]; }
missing=() bpo_missing=()
for p in "${need_pkgs[@]}"; do installed "$p" || missing+=("$p"); done
installed python3-pycotap || bpo_missing+=(python3-pycotap)
if ! installed meson || ! dpkg --compare-versions "$(dpkg-query -W -f='${Version}' meson)" ge 1.5; then
	bpo_missing+=(meson)
fi
if [ ${#missing[@]} -gt 0 ] || [ ${#bpo_missing[@]} -gt 0 ]; then
	sudo_cmd=""
	[ "$(id -u)" -eq 0 ] || sudo_cmd=sudo
	log "installing build dependencies: ${missing[*]} ${bpo_missing[*]}"
	$sudo_cmd apt-get update -qq >/dev/null || log "apt-get update reported errors; trying the install anyway"
	if [ ${#missing[@]} -gt 0 ]; then
		DEBIAN_FRONTEND=noninteractive $sudo_cmd apt-get install -y -qq --no-install-recommends \
			"${missing[@]}" >/dev/null || die "apt-get install ${missing[*]} failed"
	fi
	if [ ${#bpo_missing[@]} -gt 0 ]; then
		policy=$(apt-cache policy meson)
		grep -q "$suite" <<<"$policy" ||
			die "$suite is not in the system's apt sources (meson >= 1.5 is there): run scripts/bootstrap.sh"
		DEBIAN_FRONTEND=noninteractive $sudo_cmd apt-get install -y -qq --no-install-recommends \
			-t "$suite" "${bpo_missing[@]}" >/dev/null || die "apt-get install -t $suite ${bpo_missing[*]} failed"
	fi
fi

# 2. Key and cache layout.
patches=()
for p in "$here"/patches/*.patch; do [ -e "$p" ] && patches+=("$p"); done
key=$({
	printf '%s %s\n' "$orig" "$orig_sha256"
	for p in "${patches[@]}"; do printf '%s ' "$(basename "$p")"; sha256sum <"$p"; done
	printf '%s\n' "${config_opts[*]}" "${targets[*]}"
	sha256sum <"$0"
} | sha256sum | cut -c1-16)
srcdir=$cache/qemu-src
out=$cache/qemu/$key

publish() {
	[ $print_dir -eq 1 ] && printf '%s\n' "$out"
	return 0
}

# A complete build of this key ("ok" is written last) is used as it is.
exit_if_cached() {
	if [ -f "$out/ok" ]; then
		log "cached: $out ($(elapsed) s)"
		publish
		exit 0
	fi
}

mkdir -p "$cache/qemu" "$srcdir"
# Without the lock first: a caller whose key is built does not wait for
# another key's build. The lock serialises the builds (and their prunes);
# once it is held, the key is looked up again, since the caller it waited
# for may have just built the same key.
exit_if_cached
exec 9>"$cache/qemu/.lock"
flock 9
exit_if_cached

# 3. The orig tarball, downloaded once through a private APT configuration.
if [ ! -f "$srcdir/$orig" ] || ! echo "$orig_sha256  $srcdir/$orig" | sha256sum -c --status; then
	# shellcheck source=../../scripts/lib/debian-mirror.sh
	. "$repo/scripts/lib/debian-mirror.sh"
	mirror=$(debian_mirror) || die "cannot read the Debian mirror from /etc/apt"
	apt_dir=$srcdir/apt
	mkdir -p "$apt_dir/lists/partial" "$apt_dir/cache/archives/partial" "$apt_dir/sources.list.d"
	printf 'deb-src %s %s main\n' "$mirror" "$suite" >"$apt_dir/sources.list"
	apt_opts=(
		-o "Dir::Etc::SourceList=$apt_dir/sources.list"
		-o "Dir::Etc::SourceParts=$apt_dir/sources.list.d"
		-o "Dir::State::Lists=$apt_dir/lists"
		-o "Dir::Cache=$apt_dir/cache"
		-o "APT::Sandbox::User=root"
	)
	log "locating $orig ($suite sources, private APT configuration)"
	apt-get "${apt_opts[@]}" update -qq >&2 || die "apt-get update (private $suite deb-src list) failed"
	line=$(apt-get "${apt_opts[@]}" source --print-uris qemu 2>/dev/null | grep -F " $orig " || true)
	[ -n "$line" ] || die "$orig is not in $suite's qemu source package (any more?): $(apt-get "${apt_opts[@]}" source --print-uris qemu 2>&1 | grep -o "qemu_[^ ]*orig[^ ]*" | head -1)"
	read -r uri name size hash <<<"$line"
	uri=${uri//\'/}
	[ "$hash" = "SHA256:$orig_sha256" ] || die "$orig: the archive says $hash, expected SHA256:$orig_sha256"
	log "downloading $orig ($((size / 1048576)) MB)"
	rm -f "$srcdir/$orig.part"
	/usr/lib/apt/apt-helper "${apt_opts[@]}" download-file "$uri" "$srcdir/$orig.part" "$hash" >&2 ||
		die "download of $orig failed"
	mv "$srcdir/$orig.part" "$srcdir/$orig"
fi

# 4. Extract (without roms/: firmware sources, 269 MB, not used), patch and
#    configure. An interrupted build of the same key resumes from its
#    configured build tree.
buildlog=$out/build.log
prepare_tree() {
	rm -rf "$out"
	mkdir -p "$out/src.tmp"
	log "extracting $orig and applying ${#patches[@]} patches (log: $buildlog)"
	tar -xJf "$srcdir/$orig" -C "$out/src.tmp" --exclude="qemu-$version/roms/*/*"
	mv "$out/src.tmp/qemu-$version" "$out/src"
	rmdir "$out/src.tmp"
	for p in "${patches[@]}"; do
		printf '== patch %s\n' "$(basename "$p")" >>"$buildlog"
		patch -d "$out/src" -p1 --forward --batch <"$p" >>"$buildlog" 2>&1 ||
			{ tail -20 "$buildlog" >&2; die "patch $(basename "$p") does not apply"; }
	done

	# The "+ds" tarball has no prebuilt firmware (pc-bios/*.bz2, *.bin).
	# QEMU's meson.build lists the edk2 images as inputs of build targets
	# whenever bzip2 is installed and an edk2 target (aarch64-softmmu is one)
	# is configured: give it empty compressed stand-ins. They are never
	# installed (--disable-install-blobs); these boards need no firmware.
	local f
	for f in $(sed -n "s/^ *'\(edk2-[^']*\.fd\)',\$/\1/p" "$out/src/pc-bios/meson.build"); do
		[ -e "$out/src/pc-bios/$f.bz2" ] || bzip2 -c </dev/null >"$out/src/pc-bios/$f.bz2"
	done

	log "configuring: ${config_opts[*]}"
	mkdir -p "$out/build"
	printf '== configure --prefix=%s %s\n' "$out" "${config_opts[*]}" >>"$buildlog"
	(cd "$out/build" && ../src/configure --prefix="$out" "${config_opts[@]}") >>"$buildlog" 2>&1 ||
		{ tail -30 "$buildlog" >&2; die "configure failed"; }
	touch "$out/build/.servoamp-configured"
}
if [ -f "$out/build/.servoamp-configured" ]; then
	log "resuming the interrupted build in $out/build"
else
	prepare_tree
fi

# 5. Build, with a progress line every 30 s.
log "building ${targets[*]} with -j$jobs (log: $buildlog)"
printf '== ninja -j%s %s\n' "$jobs" "${targets[*]}" >>"$buildlog"
ninja -C "$out/build" -j"$jobs" "${targets[@]}" >>"$buildlog" 2>&1 &
ninja_pid=$!
trap 'kill "$ninja_pid" 2>/dev/null || true' EXIT
tb=$(date +%s)
while kill -0 "$ninja_pid" 2>/dev/null; do
	for _ in $(seq 30); do
		sleep 1
		kill -0 "$ninja_pid" 2>/dev/null || break
	done
	if kill -0 "$ninja_pid" 2>/dev/null; then
		log "building: $(($(date +%s) - tb)) s elapsed (log: $buildlog)"
	fi
done
wait "$ninja_pid" || { tail -30 "$buildlog" >&2; die "build failed"; }
trap - EXIT

# 6. Install the emulator (prefix = $out) and the qtests.
printf '== meson install\n' >>"$buildlog"
(cd "$out/build" && ./pyvenv/bin/meson install --no-rebuild --quiet) >>"$buildlog" 2>&1 ||
	{ tail -30 "$buildlog" >&2; die "install failed"; }
for t in "${qtests[@]}"; do
	install -D -m 0755 "$out/build/tests/qtest/$t" "$out/libexec/servoamp/$t"
done
"$out/bin/qemu-system-aarch64" --version | head -1 | grep -q "version $version" ||
	die "$out/bin/qemu-system-aarch64 does not run"
"$out/bin/qemu-system-aarch64" -M none -netdev help | grep -qx user ||
	die "qemu-system-aarch64 was built without slirp (user networking)"
"$out/bin/qemu-system-aarch64" -M help | grep -q '^xlnx-zcu102 ' || die "qemu-system-aarch64 has no xlnx-zcu102"
"$out/bin/qemu-system-aarch64" -M help | grep -q '^xilinx-zynq-a9 ' || die "qemu-system-aarch64 has no xilinx-zynq-a9"
for t in "${qtests[@]}"; do
	log "running the qtest $t (run-regression-test.sh --test $t)"
	printf '== run-regression-test.sh --test %s\n' "$t" >>"$buildlog"
	"$here/run-regression-test.sh" "$out" --test "$t" >>"$buildlog" 2>&1 ||
		{ tail -20 "$buildlog" >&2; die "the qtest $t failed"; }
done

secs=$(elapsed)
du_src=$(du -sm "$out/src" | cut -f1)
du_build=$(du -sm "$out/build" | cut -f1)
du_total=$(du -sm "$out" | cut -f1)
{
	echo "version=$version"
	echo "key=$key"
	echo "orig=$orig"
	echo "orig_sha256=$orig_sha256"
	for p in "${patches[@]}"; do echo "patch=$(basename "$p")"; done
	echo "configure=--prefix=$out ${config_opts[*]}"
	echo "jobs=$jobs"
	echo "build_seconds=$secs"
	echo "disk_mb_src=$du_src"
	echo "disk_mb_build=$du_build"
	echo "disk_mb_install=$((du_total - du_src - du_build))"
} >"$out/info"
if [ "${SERVOAMP_QEMU_KEEP_BUILD:-0}" != 1 ]; then
	rm -rf "$out/src" "$out/build"
fi
touch "$out/ok"

# 7. Prune: keep the newest complete builds.
ls -td "$cache"/qemu/*/ | tail -n +$((${SERVOAMP_KEEP:-2} + 1)) | while read -r d; do
	[ "${d%/}" = "$out" ] || rm -rf "${d%/}"
done
log "built in $secs s: $out/bin/qemu-system-aarch64 (disk: source $du_src MB, build $du_build MB, install $((du_total - du_src - du_build)) MB)"
publish
