#!/usr/bin/env bash
# Train every learned comparator of training/recipes.py (RECIPES: fixed budgets, training seeds 0-2;
# the fleet networks one seed), benchmark each run on the test seeds beside rg-mpc, export the
# validation-selected run of each recipe to agents/zoo/ and regenerate docs/LEARNED.md (about 100
# minutes of 2 cores: 69 at the last retrain of the flat networks, 24 for the two fleet networks
# side by side and 5 for the multi-agent fleet runs, `lawn zoo train --only ...`).
#   bash scripts/train_agents.sh [RUNS_DIR]   (default: runs/agents; finished runs are kept)
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh full
runs="${1:-runs/agents}"
.venv/bin/lawn zoo train --runs "$runs" --workers 2 --quiet
.venv/bin/lawn zoo build --runs "$runs" --quiet
