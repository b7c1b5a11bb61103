#!/usr/bin/env bash
# Train the shipped comparators with fixed budgets and seeds, then benchmark them beside the
# experts. Reproduces zoo/ and the learned rows of the README (about 25 minutes on 2 cores).
#   bash scripts/train_agents.sh [OUT_DIR]   (default: zoo)
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh full
out="${1:-zoo}"
lawn=.venv/bin/lawn
mkdir -p "$out"
train() { [ -f "$out/$1/model.zip" ] || "$lawn" train --quiet --out "$out/$1" "${@:2}"; }
# two at a time: one per core
train ppo-comm --algo ppo --env lawn/Comm-v0 --timesteps 200000 --seed 0 &
train ppo-joint --algo ppo --env lawn/Joint-v0 --timesteps 200000 --seed 0
wait
train sac-comm --algo sac --env lawn/Comm-v0 --timesteps 30000 --seed 0 &
train sac-joint --algo sac --env lawn/Joint-v0 --timesteps 30000 --seed 0
wait
train bc-comm --algo bc --env lawn/Comm-v0 --timesteps 4800 --seed 0 &
train bc-joint --algo bc --env lawn/Joint-v0 --timesteps 4800 --seed 0
wait
train ppo-marl --algo ppo --env lawn/Parallel-v0 --timesteps 200000 --seed 0 &
train ppo-comm-from-bc --algo ppo --env lawn/Comm-v0 --timesteps 100000 --seed 0 --init-from "$out/bc-comm"
wait
"$lawn" benchmark --env lawn/Comm-v0 --episodes 20 --seed 0 --out "$out/benchmark-comm" --quiet \
  --policies rg-mpc ao-mpc epa --include "$out/ppo-comm" "$out/sac-comm" "$out/bc-comm" "$out/ppo-comm-from-bc"
"$lawn" benchmark --env lawn/Joint-v0 --episodes 20 --seed 0 --out "$out/benchmark-joint" --quiet \
  --policies rg-mpc ao-mpc epa --include "$out/ppo-joint" "$out/sac-joint" "$out/bc-joint" "$out/ppo-marl"
