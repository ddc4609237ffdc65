#!/usr/bin/env bash
# Installs everything objscan needs on a Debian/Ubuntu machine (run as root or with sudo available):
# the system libraries open3d and pyrealsense2 load, a Python 3.11+ virtual environment in .venv, and the
# pinned Python dependencies from requirements.lock. Safe to run again: it only installs what is missing.
set -euo pipefail
cd "$(dirname "$0")/.."

SYSTEM_PACKAGES=(libusb-1.0-0 libudev1 libgomp1 libgl1 libegl1 libx11-6 python3-venv iproute2)  # iproute2: the netns test
missing=()
for pkg in "${SYSTEM_PACKAGES[@]}"; do
  dpkg -s "$pkg" >/dev/null 2>&1 || missing+=("$pkg")
done
if [ "${#missing[@]}" -gt 0 ]; then
  echo "objscan: installing system packages: ${missing[*]}"
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

PYTHON="${PYTHON:-python3}"
if ! "$PYTHON" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else 1)'; then
  echo "objscan needs Python 3.11 or newer ($PYTHON is $("$PYTHON" --version 2>&1))" >&2
  exit 1
fi
if [ ! -x .venv/bin/python ]; then
  echo "objscan: creating .venv"
  "$PYTHON" -m venv .venv
fi
stamp=.venv/.objscan-installed
if [ ! -f "$stamp" ] || [ requirements.lock -nt "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
  echo "objscan: installing Python dependencies (first time: a few minutes, ~1.5 GB)"
  .venv/bin/python -m pip install -q --upgrade pip uv
  .venv/bin/uv pip install -q --python .venv/bin/python -r requirements.lock
  .venv/bin/uv pip install -q --python .venv/bin/python --no-deps -e .
  touch "$stamp"
fi
.venv/bin/python -c 'import open3d, zenoh, pinocchio, ruckig, pyrealsense2' \
  || { echo "objscan: the installed environment does not import; see the error above" >&2; exit 1; }
