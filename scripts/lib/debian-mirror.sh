# shellcheck shell=bash
# debian_mirror: print the Debian mirror URI this machine's apt already uses
# (from /etc/apt/sources.list.d/*.sources or /etc/apt/sources.list), so that
# no registry host name is ever written into the repository. Sourced by
# scripts/bootstrap.sh, linux/initramfs/build.sh and build-rt-tests.sh, linux/kernel/build.sh.
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

# private_apt_setup ROOT [OPTION...]: a private apt configuration under ROOT:
# its own sources list (ROOT/etc/sources.list, which the caller writes),
# state, lists and cache; the machine's sources.list.d and preferences are
# not read. Sets the array PRIVATE_APT_OPTS for apt-get, the OPTIONs
# (-o ... pairs) appended. Sourced by linux/initramfs/build.sh and
# build-rt-tests.sh.
private_apt_setup() {
	local root=$1
	shift
	mkdir -p "$root/lists/partial" "$root/cache/archives/partial" "$root/etc/preferences.d"
	: >"$root/status"
	PRIVATE_APT_OPTS=(
		-o "Dir::Etc::SourceList=$root/etc/sources.list"
		-o "Dir::Etc::SourceParts=-"
		-o "Dir::Etc::PreferencesParts=$root/etc/preferences.d"
		-o "Dir::State::Lists=$root/lists"
		-o "Dir::State::Status=$root/status"
		-o "Dir::Cache=$root/cache"
		-o "Debug::NoLocking=1"
		-o "APT::Sandbox::User=root"
		"$@"
	)
}
