"""How good the RL interface's zero action is (issue #9): the anchors a learner starts from,
against ``rg-mpc`` on the same seeds, in one run.

Every row plays full 120-slot episodes of the unmodified ``lawn/Comm-v0`` scenario and reports the
realized control cost (mean and 95 % interval over seeds) and the paired per-seed difference
against ``rg-mpc``. The rows:

* ``hover`` -- the v0 interface's zero action (the drone hovers at its start, equal power);
* ``distance`` -- the anchored scheme with the distance prior (drone over the AGVs' centroid, the
  split that equalizes every link's outage), the RL interface before issue #9's stake prior;
* ``stake`` -- the anchored scheme with the stake prior (``lawn_env.interface``), the RL
  interface's default: the zero action a learner of ``lawn/CommRL-v0`` or ``lawn/JointRL-v0``
  starts from.

The seeds are the validation seeds (``training.protocol.VALIDATION_SEED_BASE`` on): the anchor was
chosen on them, never on the benchmark's test seeds.

Usage: ``python benchmarks/anchors.py [--episodes 20] [--markdown FILE]``
"""

from __future__ import annotations

import argparse
from pathlib import Path

import gymnasium as gym
import numpy as np

import lawn_env  # noqa: F401  (registers the ids)
from agents import make_policy, rollout
from training.protocol import VALIDATION_SEED_BASE
from training.tables import mean_ci, paired_difference

ENV_ID = "lawn/Comm-v0"
#: The anchors compared: the interface each zero action is decoded by (the scenario is v0's).
ANCHORS = {
    "hover": None,
    "distance": {"base": "rl", "power_anchor": "distance"},
    "stake": {"base": "rl"},
}


def zero_action_costs(interface, seeds: list[int]) -> dict[int, float]:
    """Realized control cost of the zero action decoded by ``interface``, per seed (full episodes:
    the cost reward and no termination, whatever the interface's own)."""
    iface = None if interface is None else {**interface, "reward": "cost", "termination_distance_m": None}
    env = gym.make(ENV_ID, interface=iface)
    zero = np.zeros(env.action_space.shape, dtype=np.float32)
    costs = {}
    for seed in seeds:
        env.reset(seed=seed)
        done = False
        while not done:
            _, _, terminated, truncated, info = env.step(zero)
            done = terminated or truncated
        costs[seed] = info["episode_metrics"]["control_cost"]
    return costs


def _relative(x: float, sign: bool = True) -> str:
    """A relative difference as a percentage, or as a factor once it is past 10x."""
    if abs(x) >= 10:
        return f"{x:,.0f}x" if not sign else f"{1 + x:,.0f}x the cost"
    return f"{x:+.1%}" if sign else f"{x:.1%}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--episodes", type=int, default=20, help="validation seeds (default: 20)")
    parser.add_argument("--markdown", help="also write the table of this run to this file")
    args = parser.parse_args(argv)
    seeds = [VALIDATION_SEED_BASE + i for i in range(args.episodes)]
    env = gym.make(ENV_ID)
    expert = make_policy("rg-mpc", env_id=ENV_ID)
    reference = {s: rollout(env, expert, s).metrics["control_cost"] for s in seeds}
    rows = [("rg-mpc (reference)", reference)] + [(name, zero_action_costs(i, seeds)) for name, i in ANCHORS.items()]
    lines = [f"Zero action of each anchor on {ENV_ID}, {len(seeds)} validation seeds "
             f"({seeds[0]}-{seeds[-1]}), full unmodified episodes:", "",
             "| policy | control cost | vs rg-mpc (paired) | worst seed vs rg-mpc |", "|---|---|---|---|"]
    for name, costs in rows:
        mean, half = mean_ci(costs.values())
        if costs is reference:
            lines.append(f"| {name} | {mean:,.0f} ± {half:,.0f} | – | – |")
            continue
        diff, dhalf, _ = paired_difference(costs, reference)
        worst = max(costs[s] / reference[s] - 1 for s in seeds)
        lines.append(f"| {name} | {mean:,.0f} ± {half:,.0f} | {_relative(diff)} ± {_relative(dhalf, sign=False)} "
                     f"| {_relative(worst)} |")
    text = "\n".join(lines)
    print(text)
    if args.markdown:
        Path(args.markdown).write_text(text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
