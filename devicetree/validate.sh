#!/usr/bin/env bash
# Validate servoamp's devicetree with dt-schema (the dtschema package in .venv).
#
#   devicetree/validate.sh [board]      # default board: zynq7000_qemu
#
# 1. dt-doc-validate: the servoamp bindings (devicetree/bindings/**.yaml).
# 2. dt-mk-schema: the board's kernel source's bindings (linux-source-6.1
#    for the Zynq-7000, 6.12 for the ZynqMP: board.yaml's linux.link) plus
#    ours, cached in build/dt/ by kernel source + bindings. "servoamp" is
#    not a registered vendor prefix of Linux, so the kernel bindings are
#    staged (symlinks) with a vendor-prefixes.yaml that adds it, as the
#    upstream patch adding the prefix would.
# 3. dt-validate: the board's Linux DTB (build/boards/<board>/linux.dtb,
#    built by python/servoamp/qemu.py) against them.
# Messages about servoamp's nodes fail the script. Messages about the
# upstream SoC nodes (the kernel's bindings vs. this dtschema release) and
# the board's own root compatible are printed as known.
# tests/robot/test_devicetree_validate.py runs it on every board.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
repo=$(cd "$here/.." && pwd)
board=${1:-zynq7000_qemu}
venv=$repo/.venv/bin
out=$repo/build/dt
mkdir -p "$out"

# the kernel's source (bindings, dt-bindings headers): the board's own
# kernel build when board.yaml names one (linux.link, e.g. the ZynqMP's
# 6.12), else that of any variant of the default kernel built (6.1)
ksrc=""
link=$(sed -n 's/^  link: *\([^ #]*\).*/\1/p' "$repo/boards/$board/board.yaml" 2>/dev/null || true)
kernels=(kernel-rt kernel)
[ -z "$link" ] || kernels=("${link#build/}")
for k in "${kernels[@]}"; do
	[ -n "$ksrc" ] || ksrc=$(sed -n 's/^src=//p' "$repo/build/$k/info" 2>/dev/null || true)
done
[ -d "$ksrc" ] || { echo "validate: no kernel source; run linux/kernel/build.sh" >&2; exit 1; }
dtb=$repo/build/boards/$board/linux.dtb
[ -f "$dtb" ] || { echo "validate: $dtb missing; run west emu --build-only" >&2; exit 1; }

mapfile -t bindings < <(find "$here/bindings" -name '*.yaml' | sort)
echo "[dt] dt-doc-validate ${#bindings[@]} bindings"
"$venv/dt-doc-validate" "${bindings[@]}"

key=$({ echo "$ksrc"; cat "${bindings[@]}"; "$venv/python" -c 'import dtschema; print(dtschema.__version__)'; } | sha256sum | cut -c1-16)
schema=$out/processed-schema-$key.json
if [ ! -f "$schema" ]; then
	echo "[dt] dt-mk-schema (kernel bindings + servoamp bindings)"
	stage=$out/kernel-bindings
	rm -rf "$stage"
	cp -rs "$ksrc/Documentation/devicetree/bindings" "$stage"
	rm "$stage/vendor-prefixes.yaml"
	awk '/^  "\^semtech,\.\*":/ && !done { print "  \"^servoamp,.*\":"; print "    description: servoamp, open-source AMP framework for motion control"; done = 1 } { print }' \
		"$ksrc/Documentation/devicetree/bindings/vendor-prefixes.yaml" >"$stage/vendor-prefixes.yaml"
	grep -q '"^servoamp,' "$stage/vendor-prefixes.yaml" || { echo "validate: cannot add the vendor prefix" >&2; exit 1; }
	"$venv/dt-mk-schema" -j "$stage" "$here/bindings" >"$schema.tmp" 2>"$out/mk-schema.log"
	mv "$schema.tmp" "$schema"
fi

echo "[dt] dt-validate $dtb"
"$venv/dt-validate" -s "$schema" "$dtb" >"$out/validate-$board.log" 2>&1 || true
ours=$(grep -E '^[^[:space:]].*(servoamp|remoteproc@|ocm-mailbox@|cycle-interrupt@|reserved-memory|servo-carveout)' "$out/validate-$board.log" |
	grep -v '^[^:]*: / (servoamp,' || true)
known=$(grep -cE '^[^[:space:]]' "$out/validate-$board.log" || true)
if [ -n "$ours" ]; then
	echo "$ours"
	echo "[dt] FAIL: dt-validate reports problems in servoamp's nodes (log: $out/validate-$board.log)"
	exit 1
fi
echo "[dt] servoamp nodes (reserved-memory carveout, ocm-mailbox, cycle-interrupt, remoteproc): no findings"
echo "[dt] $known finding(s) in upstream/board-level nodes, listed in $out/validate-$board.log:"
grep -E '^[^[:space:]]' "$out/validate-$board.log" | sed 's/^[^:]*: /  /' | cut -c1-110
