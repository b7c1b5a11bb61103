#!/usr/bin/env bash
# Regenerate every figure and table of the README and the docs pages (docs/) from the current code, each
# stamped with the package version and git commit it came from (training/provenance.py). A generated
# block lives in one page (README.md or docs/*.md); `python -m training.readme NAME FILE` finds it:
#   docs/REPRODUCTION.md, docs/figures/reproduction/   lawn figures (the paper's experiments)
#   blocks benchmark (README), benchmark-nominal        lawn benchmark (+ docs/figures/benchmark.png)
#   block gap (docs/experts.md)                         lawn gap (+ docs/figures/gap.png, convergence.png)
#   blocks dv-mpc, dv-mpc-refinements (docs/experts.md), beyond-the-paper (docs/REPRODUCTION.md)   (--only dv)
#                                                       benchmarks/dv_mpc.py: dv-mpc against rg-mpc on the suite
#   blocks expert-speed, env-throughput, train-throughput, vector-step   benchmarks/*.py --markdown
#   block parallel-scaling (docs/performance.md)        benchmarks/parallel_scaling.py (--only parallel)
#   blocks numba-jit, qp-speed (--only qp)              benchmarks/{numba_jit,qp_speed}.py
#   block fleet-decision (docs/performance.md; --only fleet)   benchmarks/fleet_decision.py
#   block anchors (docs/rl.md; with learned)            benchmarks/anchors.py --markdown
#   docs/LEARNED.md                                     lawn zoo build (needs the training runs in
#                                                       runs/agents: with --train, scripts/train_agents.sh
#                                                       trains them first: about 100 min on 2 cores,
#                                                       `time bash scripts/train_agents.sh`; with the fleet
#                                                       runs only, their block zoo-fleet alone)
#   block zoo-drift (docs/training.md)                  benchmarks/zoo_drift.py (the table's shipped agents
#                                                       and experts re-evaluated at the current code)
#   docs/LEADERBOARD.md                                 lawn benchmark --suite (--only suite; about 17
#                                                       minutes on 2 cores), with block fleet-generalization
#                                                       (docs/LEARNED.md: the fleet networks on K = 3..64)
#                                                       and block fast-drone-grid
#                                                       (docs/benchmark.md: benchmarks/fast_drone_grid.py)
#   docs/figures/episodes/*.gif                         lawn render (--only render): the README's animation
#                                                       (rg-mpc, default task), a learned agent, the disturbed preset
#   bash scripts/refresh_docs.sh [--train] [--only NAME ...]
# Generated data goes to runs/ (not committed). Timed benchmarks are run one at a time.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh full
train=0
only=()
while [ $# -gt 0 ]; do
  case "$1" in
    --train) train=1 ;;
    --only) shift; while [ $# -gt 0 ] && [[ "$1" != --* ]]; do only+=("$1"); shift; done; continue ;;
    *) echo "usage: scripts/refresh_docs.sh [--train] [--only figures|benchmark|gap|dv|speed|throughput|parallel|qp|fleet|learned|suite|render ...]" >&2; exit 2 ;;
  esac
  shift
done
want() { [ ${#only[@]} -eq 0 ] || [[ " ${only[*]} " == *" $1 "* ]]; }
lawn=.venv/bin/lawn
py=.venv/bin/python
splice() { "$py" -m training.readme "$1" "$2" --source "$3"; }
mkdir -p runs/gap docs/figures

if want figures; then
  rm -rf runs/figures  # from scratch: every row from the current code, and the build time recorded
  "$lawn" figures --out runs/figures --docs docs --workers 2 --quiet
fi
if want benchmark; then
  "$lawn" benchmark --episodes 20 --seed 0 --out runs/benchmark --quiet
  splice benchmark runs/benchmark/summary.md "lawn benchmark --episodes 20 --seed 0"
  "$py" -m training.digests --write  # the table's rows' recorded episodes (tests/test_digests.py), with the table
  cp runs/benchmark/benchmark.png docs/figures/benchmark.png
  "$lawn" benchmark --preset paper-nominal --episodes 5 --policies ao-mpc epa sf pid lqr --out runs/benchmark-nominal --quiet
  splice benchmark-nominal runs/benchmark-nominal/summary.md \
    "lawn benchmark --preset paper-nominal --episodes 5 --policies ao-mpc epa sf pid lqr"
fi
if want gap; then
  "$lawn" gap --policies ao-mpc rg-mpc --driver ao-mpc --episodes 5 --every 3 --seed 0 --out runs/gap --quiet \
    | tee runs/gap/stdout.txt
  splice gap runs/gap/gap_summary.md "lawn gap --policies ao-mpc rg-mpc --driver ao-mpc --episodes 5 --every 3 --seed 0"
  cp runs/gap/gap.png docs/figures/gap.png
  cp runs/gap/convergence.png docs/figures/convergence.png
fi
if want dv; then  # dv-mpc against rg-mpc: every suite task, two seed ranges (about 15 minutes on 2 cores)
  "$py" benchmarks/dv_mpc.py --markdown runs/dv_mpc.md
  splice dv-mpc runs/dv_mpc.md "python benchmarks/dv_mpc.py"
  splice beyond-the-paper runs/dv_mpc.md "python benchmarks/dv_mpc.py"
  refinements=(--tasks steady steady-low-power disturbed --episodes 40 --variant terminal_success=0.8
               --variant terminal_success=0.6 --variant model_lag=0 --variant filter_measurements=0 --no-timing)
  "$py" benchmarks/dv_mpc.py "${refinements[@]}" --markdown runs/dv_mpc_refinements.md
  splice dv-mpc-refinements runs/dv_mpc_refinements.md "python benchmarks/dv_mpc.py ${refinements[*]}"
fi
if want speed; then
  "$py" benchmarks/expert_speed.py --tolerance-sweep --markdown runs/expert_speed.md
  splice expert-speed runs/expert_speed.md "python benchmarks/expert_speed.py --tolerance-sweep"
fi
if want throughput; then
  "$py" benchmarks/env_throughput.py --markdown runs/env_throughput.md
  splice env-throughput runs/env_throughput.md "python benchmarks/env_throughput.py"
  "$py" benchmarks/train_throughput.py --markdown runs/train_throughput.md
  splice train-throughput runs/train_throughput.md "python benchmarks/train_throughput.py"
  "$py" benchmarks/vector_step_breakdown.py --markdown runs/vector_step.md
  splice vector-step runs/vector_step.md "python benchmarks/vector_step_breakdown.py"
fi
if want parallel; then  # the 16-core block (parallel-scaling-16) is measured once, on such a machine
  "$py" benchmarks/parallel_scaling.py --markdown runs/parallel_scaling.md
  splice parallel-scaling runs/parallel_scaling.md "python benchmarks/parallel_scaling.py"
fi
if want qp; then
  "$py" benchmarks/numba_jit.py --markdown runs/numba_jit.md
  splice numba-jit runs/numba_jit.md "python benchmarks/numba_jit.py"
  "$py" benchmarks/qp_speed.py --markdown runs/qp_speed.md
  splice qp-speed runs/qp_speed.md "python benchmarks/qp_speed.py"
fi
if want fleet; then
  "$py" benchmarks/fleet_decision.py --markdown runs/fleet_decision.md
  splice fleet-decision runs/fleet_decision.md "python benchmarks/fleet_decision.py"
fi
if want learned; then
  "$py" benchmarks/anchors.py --markdown runs/anchors.md
  splice anchors runs/anchors.md "python benchmarks/anchors.py"
  if [ "$train" = 1 ]; then
    bash scripts/train_agents.sh runs/agents
  elif [ -d runs/agents ]; then
    "$lawn" zoo build --runs runs/agents --quiet
  fi
  # the shipped agents and the experts re-evaluated against the table's recorded episodes
  if "$py" benchmarks/zoo_drift.py --markdown runs/zoo_drift.md; then
    splice zoo-drift runs/zoo_drift.md "python benchmarks/zoo_drift.py"
  else
    splice zoo-drift runs/zoo_drift.md "python benchmarks/zoo_drift.py"
    echo "refresh_docs: the learned-agents table no longer holds at this code: rebuild it with --train" >&2
    exit 3
  fi
fi
if want suite; then
  "$lawn" benchmark --suite --docs docs --out runs/suite --workers 2 --quiet | tee runs/suite-stdout.txt
  "$py" benchmarks/fast_drone_grid.py > runs/fast_drone_grid.md
  splice fast-drone-grid runs/fast_drone_grid.md "python benchmarks/fast_drone_grid.py"
fi
if want render; then
  mkdir -p docs/figures/episodes
  "$lawn" render --policy rg-mpc --env lawn/Joint-v0 --seed 0 --every 2 --out docs/figures/episodes/rg-mpc.gif
  "$lawn" render --policy zoo:ppo-comm --env lawn/Comm-v0 --seed 0 --every 2 --out docs/figures/episodes/zoo-comm.gif
  "$lawn" render --policy rg-mpc --env lawn/Joint-v0 --preset disturbed --seed 0 --every 2 \
    --out docs/figures/episodes/rg-mpc-disturbed.gif
fi
echo "refresh_docs: done; review with git diff README.md docs/"
