#!/bin/sh
# Regenerates python/servoamp/schemas/servoamp_pb2.py from servoamp.proto
# (protoc from grpcio-tools, a dev dependency in pyproject.toml).
# tests/recorder/test_bridge.py checks that the checked-in file is current.
set -e
top=$(cd "$(dirname "$0")/../.." && pwd)
py=${PYTHON:-$top/.venv/bin/python}
cd "$top/python/servoamp/schemas"
"$py" -m grpc_tools.protoc -I. --python_out=. --pyi_out=. servoamp.proto
