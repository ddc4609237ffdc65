#!/usr/bin/env bash
# Sets up everything (scripts/install.sh) and runs the main job: a full simulated 12-view acquisition of a
# HOPE object through all services, each its own process, over Zenoh on loopback. Prints the model's path
# and its accuracy against ground truth. Arguments go to 'objscan scan' (e.g. --object orange_juice).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install.sh
export OMP_NUM_THREADS="${OMP_NUM_THREADS:-2}"
out="sessions/demo-$(date +%Y%m%d-%H%M%S)"
exec .venv/bin/objscan scan --object milk --views 12 --profile robot-turned --seed 1 --out "$out" "$@"
