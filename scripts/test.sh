#!/usr/bin/env bash
# Sets up everything with the development tools (scripts/install.sh --dev: requirements-dev.lock) and runs
# the test suite. Extra arguments go to pytest, e.g.
#   bash scripts/test.sh -m slow          # only the slow cases
#   bash scripts/test.sh tests/common     # one folder
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install.sh --dev
export OMP_NUM_THREADS="${OMP_NUM_THREADS:-1}"
if [ "$#" -eq 0 ]; then
  set -- -m "not slow"
fi
exec .venv/bin/python -m pytest "$@"
