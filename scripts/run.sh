#!/usr/bin/env bash
# Set up the core environment (.venv) and run the main job. Extra arguments go to it.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh core
exec .venv/bin/lawn benchmark --episodes 20 --seed 0 --out runs/benchmark --overwrite "$@"  # the main job owns runs/benchmark
