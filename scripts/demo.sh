#!/usr/bin/env bash
# Sets up everything (scripts/install.sh) and runs the main job: a full simulated 12-view acquisition of the
# demo object `carton` (a milk carton made by services/sim/demo_meshes.py, part of the repository) through all
# services, each its own process, over Zenoh on loopback, with MuJoCo contact physics for the grasps and
# set-downs. Prints the model's path and its accuracy against ground truth. Arguments go to 'objscan scan'
# (e.g. --object can, --object flat_box, or --object PATH for your own mesh).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install.sh
export OMP_NUM_THREADS="${OMP_NUM_THREADS:-2}"
out="sessions/demo-$(date +%Y%m%d-%H%M%S)"
exec .venv/bin/objscan scan --object can --views 12 --profile robot-turned --seed 1 --out "$out" "$@"
