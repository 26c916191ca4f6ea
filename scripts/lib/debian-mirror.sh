# shellcheck shell=bash
# debian_mirror: print the Debian mirror URI this machine's apt already uses
# (from /etc/apt/sources.list.d/*.sources or /etc/apt/sources.list), so that
# no registry host name is ever written into the repository. Sourced by
# scripts/bootstrap.sh and linux/initramfs/build.sh.
debian_mirror() {
	local f uri=""
	for f in /etc/apt/sources.list.d/*.sources; do
		[ -r "$f" ] || continue
		uri=$(awk '/^URIs:/ { for (i = 2; i <= NF; i++) if ($i !~ /security/) { print $i; exit } }' "$f")
		[ -n "$uri" ] && break
	done
	if [ -z "$uri" ] && [ -r /etc/apt/sources.list ]; then
		uri=$(awk '$1 == "deb" && $0 !~ /security/ { for (i = 2; i <= NF; i++) if ($i ~ /^[a-z]+:\/\//) { print $i; exit } }' /etc/apt/sources.list)
	fi
	if [ -z "$uri" ]; then
		echo "cannot find the Debian mirror in /etc/apt" >&2
		return 1
	fi
	printf '%s\n' "${uri%/}"
}
