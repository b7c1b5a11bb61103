#!/usr/bin/env bash
# Set up the core environment (.venv) and run the main job. Extra arguments go to it.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh core
exec .venv/bin/lawn demo --seed 0 --out runs/demo "$@"
