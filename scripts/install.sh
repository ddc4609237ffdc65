#!/usr/bin/env bash
# Installs everything objscan needs on a Debian/Ubuntu machine (run as root or with sudo available):
# the system libraries open3d and pyrealsense2 load, a Python 3.11+ virtual environment in .venv, and the
# pinned runtime dependencies from requirements.lock. With --dev (scripts/test.sh) also the development
# tools from requirements-dev.lock (pytest, hypothesis, ruff, atheris, ...); the image and demo.sh never
# get them. Safe to run again: it only installs what is missing.
#
# Python: the system python3 when it is 3.11 or newer (Debian 12, Ubuntu 24.04); otherwise the
# distribution's python3.11 package (Ubuntu 22.04 ships it in universe beside its default 3.10), installed
# with apt. PYTHON=/path/to/python3.x overrides the choice.
set -euo pipefail
cd "$(dirname "$0")/.."

DEV=0
for arg in "$@"; do
  case "$arg" in
    --dev) DEV=1 ;;
    *) echo "usage: scripts/install.sh [--dev]" >&2; exit 2 ;;
  esac
done

SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
apt_install() {
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "$@" >/dev/null
}

SYSTEM_PACKAGES=(libusb-1.0-0 libudev1 libgomp1 libgl1 libegl1 libx11-6 python3-venv iproute2)  # iproute2: the netns test
missing=()
for pkg in "${SYSTEM_PACKAGES[@]}"; do
  dpkg -s "$pkg" >/dev/null 2>&1 || missing+=("$pkg")
done
if [ "${#missing[@]}" -gt 0 ]; then
  echo "objscan: installing system packages: ${missing[*]}"
  apt_install "${missing[@]}"
fi

new_enough() { "$1" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else 1)' 2>/dev/null; }
PYTHON="${PYTHON:-python3}"
if ! new_enough "$PYTHON"; then
  if ! command -v python3.11 >/dev/null 2>&1 || ! dpkg -s python3.11-venv >/dev/null 2>&1; then
    echo "objscan: $PYTHON is $("$PYTHON" --version 2>&1); installing the distribution's python3.11"
    apt_install python3.11 python3.11-venv \
      || { echo "objscan needs Python 3.11 or newer and this system offers no python3.11 package;" \
                "set PYTHON=/path/to/python3.11 (see README, 'Platforms')" >&2; exit 1; }
  fi
  PYTHON=python3.11
fi
if [ ! -x .venv/bin/python ]; then
  echo "objscan: creating .venv with $("$PYTHON" --version)"
  "$PYTHON" -m venv .venv
fi
install_lock() {  # lock file, stamp: install when the lock or pyproject changed since the stamp
  local lock=$1 stamp=$2
  if [ ! -f "$stamp" ] || [ "$lock" -nt "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
    echo "objscan: installing Python dependencies from $lock (first time: a few minutes, ~1.5 GB)"
    .venv/bin/python -m pip install -q --upgrade pip uv
    .venv/bin/uv pip install -q --compile-bytecode --python .venv/bin/python -r "$lock"
    .venv/bin/uv pip install -q --python .venv/bin/python --no-deps -e .
    touch "$stamp"
  fi
}
install_lock requirements.lock .venv/.objscan-installed
if [ "$DEV" -eq 1 ]; then
  install_lock requirements-dev.lock .venv/.objscan-dev-installed
fi
# Bytecode for every installed package and for objscan's own modules, written now: a process that may not
# write it (PYTHONDONTWRITEBYTECODE, a read-only install) otherwise compiles open3d's, scipy's and
# scikit-learn's Python sources again at every start, seconds of CPU per command. Python checks each file's
# timestamp, so a source edited later is compiled afresh, never run stale. Once per environment for the
# packages (a venv installed before this step gets it on the next run), every time for objscan's modules.
if [ ! -f .venv/.objscan-bytecode ]; then
  echo "objscan: compiling the installed packages' bytecode (once)"
  .venv/bin/python -m compileall -q -j 0 .venv/lib/python3*/site-packages >/dev/null || true
  touch .venv/.objscan-bytecode
fi
.venv/bin/python -m compileall -q -j 0 common services bench >/dev/null || true
.venv/bin/python -c 'import open3d, zenoh, pinocchio, ruckig, pyrealsense2, rerun, foxglove' \
  || { echo "objscan: the installed environment does not import; see the error above" >&2; exit 1; }
