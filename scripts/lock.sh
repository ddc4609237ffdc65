#!/usr/bin/env bash
# Regenerates the two locks from pyproject.toml, keeping every version already pinned (the old locks are
# constraints), so adding one dependency does not move the others:
#   requirements.lock      runtime only: what the image, demo.sh and 'scripts/install.sh' install
#   requirements-dev.lock  runtime + the 'test' extra (pytest, hypothesis, ruff, atheris, ...): scripts/test.sh
# The dev lock is resolved with the runtime lock as a constraint, so both pin the same runtime versions.
set -euo pipefail
cd "$(dirname "$0")/.."
UV="${UV:-.venv/bin/uv}"
tmp=$(mktemp -d); trap 'rm -rf "$tmp"' EXIT
cp requirements.lock "$tmp/old.lock"; [ -f requirements-dev.lock ] && cp requirements-dev.lock "$tmp/old-dev.lock"
touch "$tmp/old-dev.lock"
"$UV" pip compile pyproject.toml -o requirements.lock --python-version 3.11 -q \
  -c "$tmp/old.lock" -c "$tmp/old-dev.lock" --custom-compile-command "bash scripts/lock.sh"
"$UV" pip compile pyproject.toml --extra test -o requirements-dev.lock --python-version 3.11 -q \
  -c requirements.lock -c "$tmp/old-dev.lock" -c "$tmp/old.lock" --custom-compile-command "bash scripts/lock.sh"
# the old locks are constraints only for this run: their temporary paths are no provenance worth keeping
sed -i '\#-c /tmp/#d' requirements.lock requirements-dev.lock
echo "requirements.lock: $(grep -c '==' requirements.lock) packages; requirements-dev.lock: $(grep -c '==' requirements-dev.lock)"
