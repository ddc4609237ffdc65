#!/bin/sh
# Make the lab CA and one certificate per identity in deploy/certs (see docs/security.md).
# Usage: deploy/gen-certs.sh [--router-name my-box.lab] [--force]
set -eu
cd "$(dirname "$0")/.."
PY="${PYTHON:-python3}"
[ -x .venv/bin/python ] && PY=.venv/bin/python
exec "$PY" -m services.cli.cmd_certs --out deploy/certs "$@"
