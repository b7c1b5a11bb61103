#!/usr/bin/env bash
# Train every learned comparator of training/recipes.py (RECIPES: fixed budgets, training seeds 0-2;
# the fleet networks one seed), benchmark each run on the test seeds beside the experts, export the
# validation-selected run of each recipe to agents/zoo/ and regenerate docs/LEARNED.md. Not timed end
# to end; its parts, two runs side by side on 2 cores: about 52 minutes for the other flat networks, 24 for the two
# fleet networks, 5 for the multi-agent fleet runs, 10 for dv-joint and dv-comm (about 610 s a run) and 8
# for ppo-dv-residual (about 495 s a run), about 63 for the from-scratch recipes and the ladder's
# (15 runs of 10 M steps; the wall times are in LEARNED.md): about 160 minutes of training in all (`lawn zoo train --only ...`),
# then the build's test episodes (about 10 minutes for the steady-task agents) and the ladder's
# (python -m paper.ladder, about 5 minutes; its block reads runs/agents).
#   bash scripts/train_agents.sh [RUNS_DIR]   (default: runs/agents; finished runs are kept)
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh full
runs="${1:-runs/agents}"
.venv/bin/lawn zoo train --runs "$runs" --workers 2 --quiet
.venv/bin/lawn zoo build --runs "$runs" --quiet
PATH="$PWD/.venv/bin:$PATH" .venv/bin/python -m paper.pages refresh --only zoo-ladder
