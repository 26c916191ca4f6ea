#!/usr/bin/env bash
# The demo's last step: boot the emulated controller with networking, run
# `servoamp bridge` for N seconds (live on the printed ws:// address, every
# cycle into build/demo/run.mcap through the Foxglove SDK; a parameter set
# through the bridge and a firmware hang/recovery on record), plots into
# build/demo/plots/, and print `servoamp info`. Arguments go to
# python -m servoamp.demo_record (--seconds N, --out DIR, --keep-logs,
# --no-fault, --program, --can, --board B, --ws-port P).
set -euo pipefail
here=$(cd "$(dirname "$0")/../.." && pwd)
cd "$here"
exec .venv/bin/python -m servoamp.demo_record "$@"
