#!/usr/bin/env bash
# Regenerate every generated table and figure of the README and the docs pages from the current code.
# The blocks' markers name the command and the table file that fill them (paper/pages.py); this
# runs `python -m paper.pages refresh`, each distinct command once, one at a time, then the
# episode animations (lawn render). --only takes block names or groups (figures benchmark gap dv
# speed throughput parallel qp fleet learned suite reference clients) and render; --train retrains the agents first
# (scripts/train_agents.sh; each run's wall time is in docs/LEARNED.md). Generated data goes to runs/ (not committed).
#   bash scripts/refresh_docs.sh [--train] [--only NAME ...]
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh full
train=0
only=()
while [ $# -gt 0 ]; do
  case "$1" in
    --train) train=1 ;;
    --only) shift; while [ $# -gt 0 ] && [[ "$1" != --* ]]; do only+=("$1"); shift; done; continue ;;
    *) echo "usage: scripts/refresh_docs.sh [--train] [--only NAME|GROUP|render ...]" >&2; exit 2 ;;
  esac
  shift
done
blocks=()
for name in "${only[@]}"; do [ "$name" = render ] || blocks+=("$name"); done
mkdir -p runs docs/figures
if [ "$train" = 1 ]; then
  bash scripts/train_agents.sh runs/agents
fi
if [ ${#only[@]} -eq 0 ] || [ ${#blocks[@]} -gt 0 ]; then
  .venv/bin/python -m paper.pages refresh ${blocks[@]:+--only "${blocks[@]}"}
fi
if [ ${#only[@]} -eq 0 ] || [[ " ${only[*]} " == *" render "* ]]; then
  lawn=.venv/bin/lawn
  mkdir -p docs/figures/episodes
  "$lawn" render --policy rg-mpc --env lawn/Joint-v1 --seed 0 --every 2 --overwrite --out docs/figures/episodes/rg-mpc.gif
  "$lawn" render --policy zoo:ppo-comm --env lawn/Comm-v1 --seed 0 --every 2 --overwrite --out docs/figures/episodes/zoo-comm.gif
  "$lawn" render --policy rg-mpc --env lawn/Joint-v1 --preset disturbed --seed 0 --every 2 --overwrite \
    --out docs/figures/episodes/rg-mpc-disturbed.gif
fi
echo "refresh_docs: done; review with git diff README.md docs/"
