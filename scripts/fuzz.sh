#!/usr/bin/env bash
# The fuzzing campaign: every libFuzzer harness of tests/fuzz/ and the
# Python (Hypothesis) harness of the telemetry decoder (or the ones named),
# one after the other, N seconds each from its seed corpus and the
# corpus grown by earlier campaigns (build/fuzz/corpus/), then a table per
# harness: executions, exec/s, corpus size, coverage, findings. Exit 1 if
# anything was found (inputs in build/fuzz/findings/<name>/).
#
#   scripts/fuzz.sh [--seconds N] [NAME...]     (default 300 s; names:
#                                                amp_ocm gcode telem_client rproc_check
#                                                telemetry_py)
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
py="$here/.venv/bin/python"
[ -x "$py" ] || py=python3
exec "$py" "$here/tests/fuzz/fuzzrun.py" campaign "$@"
