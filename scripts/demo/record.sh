#!/usr/bin/env bash
# The demo's last step: boot the emulated controller with networking, record
# N seconds of every cycle (a parameter change and a firmware hang/recovery
# on record) into build/demo/run.mcap, plots into build/demo/plots/, and
# print `servoamp info`. Arguments go to python -m servoamp.demo_record
# (--seconds N, --out DIR, --keep-logs, --no-fault).
set -euo pipefail
here=$(cd "$(dirname "$0")/../.." && pwd)
cd "$here"
exec .venv/bin/python -m servoamp.demo_record "$@"
