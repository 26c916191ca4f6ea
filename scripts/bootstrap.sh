#!/usr/bin/env bash
# Install everything servoamp needs, idempotently: Debian packages, our own
# QEMU (emulator/qemu/build.sh, cached; bookworm-backports for its meson)
# and a Python virtual environment in .venv with the host tools. Safe to run
# again; a second run costs seconds.
#
#   scripts/bootstrap.sh            # everything (host + emulated board)
#   SERVOAMP_BOOTSTRAP=host scripts/bootstrap.sh   # host tools only
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
cd "$here"
scope=${SERVOAMP_BOOTSTRAP:-all}

log() { printf '[bootstrap] %s\n' "$*"; }
# apt's and pip's own output goes to this log; its tail is shown on failure
blog=$here/build/bootstrap.log
mkdir -p "$here/build"
quiet() {
	if ! "$@" >>"$blog" 2>&1; then
		tail -n 30 "$blog" >&2
		log "failed: $* (whole log: $blog)"
		return 1
	fi
}
sudo_cmd=""
[ "$(id -u)" -eq 0 ] || sudo_cmd="sudo"

# The Debian mirror this machine already uses, read from its own apt
# configuration: no host name is ever written into the repository.
. "$here/scripts/lib/debian-mirror.sh"

apt_host=(build-essential gcc make pkg-config python3-venv git
	gcc-arm-none-eabi libnewlib-arm-none-eabi binutils-arm-none-eabi
	clang libclang-rt-14-dev spin chromium openssl util-linux)
apt_board=(gcc-arm-linux-gnueabihf binutils-arm-linux-gnueabihf
	device-tree-compiler linux-source-6.1 bc bison flex libssl-dev
	libelf-dev cpio xz-utils kmod python3-minimal libc6-dev-armhf-cross
	gcc-aarch64-linux-gnu binutils-aarch64-linux-gnu libc6-dev-arm64-cross
	linux-source-6.12 dpkg-dev)
# From bookworm-backports: Debian's qemu-system-aarch64 (10.0.2, upstream,
# without our patches): python/servoamp/runner.py uses it only when our
# build (emulator/qemu/build.sh, which makes the same binary with the
# patches) has none, and says so; and it is the unpatched QEMU the docs
# compare against.
apt_board_bpo=(qemu-system-arm)

missing=()
want=("${apt_host[@]}")
[ "$scope" = host ] || want+=("${apt_board[@]}")
for p in "${want[@]}"; do
	dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "ok installed" || missing+=("$p")
done
missing_bpo=()
if [ "$scope" != host ]; then
	for p in "${apt_board_bpo[@]}"; do
		dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "ok installed" || missing_bpo+=("$p")
	done
fi

# bookworm-backports (meson >= 1.5 for our QEMU build): the system's sources
# get one list file with the machine's own mirror.
bpo_list=/etc/apt/sources.list.d/servoamp-backports.list
need_bpo=0
[ "$scope" = host ] || [ -f "$bpo_list" ] || need_bpo=1

if [ ${#missing[@]} -gt 0 ] || [ ${#missing_bpo[@]} -gt 0 ] || [ $need_bpo -eq 1 ]; then
	if [ $need_bpo -eq 1 ]; then
		mirror=$(debian_mirror)
		log "adding bookworm-backports from $bpo_list"
		echo "deb $mirror bookworm-backports main" | $sudo_cmd tee "$bpo_list" >/dev/null
	fi
	log "apt-get update"
	quiet $sudo_cmd apt-get update -q || log "apt-get update reported errors; continuing (log: $blog)"
	if [ ${#missing[@]} -gt 0 ]; then
		log "installing: ${missing[*]}"
		quiet $sudo_cmd env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends "${missing[@]}"
	fi
	if [ ${#missing_bpo[@]} -gt 0 ]; then
		log "installing from bookworm-backports: ${missing_bpo[*]}"
		quiet $sudo_cmd env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends \
			-t bookworm-backports "${missing_bpo[@]}"
	fi
fi

# Python: a virtual environment with the host tools, keyed by pyproject.toml.
venv="$here/.venv"
stamp="$venv/.servoamp-stamp"
key=$(cat pyproject.toml | sha256sum | cut -d' ' -f1)
if [ ! -x "$venv/bin/python" ] || [ "$(cat "$stamp" 2>/dev/null)" != "$key" ]; then
	log "creating Python environment in .venv"
	quiet python3 -m venv "$venv"
	quiet "$venv/bin/python" -m pip install --upgrade pip
	quiet "$venv/bin/python" -m pip install -e ".[dev]"
	echo "$key" >"$stamp"
fi
# Node, each keyed by its lock file: the independent MCAP reader used by
# tests/recorder (tools/mcap-verify), and Foxglove Studio's web build with
# playwright-core for the live-view test in Chromium (tools/viewer, tests/viewer).
for nd in mcap-verify viewer; do
	mv_dir="$here/tools/$nd"; mv_key=$(sha256sum "$mv_dir/package-lock.json" | cut -d' ' -f1)
	if command -v npm >/dev/null && { [ ! -d "$mv_dir/node_modules" ] || [ "$(cat "$mv_dir/node_modules/.servoamp-stamp" 2>/dev/null)" != "$mv_key" ]; }; then
		log "npm ci in tools/$nd"
		(cd "$mv_dir" && quiet npm ci --no-audit --no-fund --ignore-scripts --loglevel=error) && echo "$mv_key" >"$mv_dir/node_modules/.servoamp-stamp"
	fi
done
# Our QEMU (Debian's source + emulator/qemu/patches), cached by its inputs:
# about 10 minutes the first time, a second afterwards.
[ "$scope" = host ] || emulator/qemu/build.sh
log "ready ($scope)"
