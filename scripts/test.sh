#!/usr/bin/env bash
# The whole test suite: installs what is needed (scripts/bootstrap.sh), then
# runs every test under tests/ with pytest (host C tests, sanitizers, the
# stress test, the motion pipeline, and the Robot Framework suites on the
# emulated board). Extra arguments are passed to pytest.
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
cd "$here"
scripts/bootstrap.sh
exec .venv/bin/python -m pytest tests "$@"
