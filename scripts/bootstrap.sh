#!/usr/bin/env bash
# Install everything servoamp needs, idempotently: Debian packages (with
# bookworm-backports for QEMU >= 9.1) and a Python virtual environment in
# .venv with the host tools. Safe to run again; a second run costs seconds.
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
	gcc-arm-none-eabi libnewlib-arm-none-eabi binutils-arm-none-eabi)
apt_board=(gcc-arm-linux-gnueabihf binutils-arm-linux-gnueabihf
	device-tree-compiler linux-source-6.1 bc bison flex libssl-dev
	libelf-dev cpio xz-utils kmod python3-minimal libc6-dev-armhf-cross)

missing=()
want=("${apt_host[@]}")
[ "$scope" = host ] || want+=("${apt_board[@]}")
for p in "${want[@]}"; do
	dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "ok installed" || missing+=("$p")
done

need_qemu=0
if [ "$scope" != host ]; then
	if ! command -v qemu-system-arm >/dev/null ||
		! qemu-system-arm --version | awk 'NR==1 { split($4, v, "."); exit !(v[1] > 9 || (v[1] == 9 && v[2] >= 1)) }'; then
		need_qemu=1
	fi
fi

if [ ${#missing[@]} -gt 0 ] || [ $need_qemu -eq 1 ]; then
	if [ $need_qemu -eq 1 ]; then
		list=/etc/apt/sources.list.d/servoamp-backports.list
		if [ ! -f "$list" ]; then
			mirror=$(debian_mirror)
			log "adding bookworm-backports from $list"
			echo "deb $mirror bookworm-backports main" | $sudo_cmd tee "$list" >/dev/null
		fi
	fi
	log "apt-get update"
	quiet $sudo_cmd apt-get update -q || log "apt-get update reported errors; continuing (log: $blog)"
	if [ ${#missing[@]} -gt 0 ]; then
		log "installing: ${missing[*]}"
		quiet $sudo_cmd env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends "${missing[@]}"
	fi
	if [ $need_qemu -eq 1 ]; then
		log "installing qemu-system-arm from bookworm-backports"
		quiet $sudo_cmd env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends \
			-t bookworm-backports qemu-system-arm
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
# Node: the independent MCAP reader used by tests/recorder (tools/mcap-verify).
mv_dir="$here/tools/mcap-verify"; mv_key=$(sha256sum "$mv_dir/package-lock.json" | cut -d' ' -f1)
if command -v npm >/dev/null && { [ ! -d "$mv_dir/node_modules" ] || [ "$(cat "$mv_dir/node_modules/.servoamp-stamp" 2>/dev/null)" != "$mv_key" ]; }; then
	log "npm ci in tools/mcap-verify"
	(cd "$mv_dir" && quiet npm ci --no-audit --no-fund --ignore-scripts --loglevel=error) && echo "$mv_key" >"$mv_dir/node_modules/.servoamp-stamp"
fi
log "ready ($scope)"
