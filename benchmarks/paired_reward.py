"""What the paired reward (training.paired) does to the returns a learner sees: their spread over
seeds with and without pairing, for learners near and far from the anchor (``dv-mpc``).

The learners, each on ``lawn/Joint-v1`` with the RL interface's scaled reward and termination:

* ``zero action``: the RL interface's zero action (the anchored scheme, the stake prior, the MPC's
  increments), where an RL run on the interface starts;
* ``dv-mpc, 1.4 m grid``: ``dv-mpc`` with a drone grid of 1.4 m instead of 1.5 m (the suite's noise
  floor row): a policy next to the anchor, as a residual learner on ``dv-mpc`` starts;
* ``rg-mpc``: the paper's exact expert, a different good policy.

Each validation seed plays one full episode of a learner with the reward paired against the
anchor and records both the env's own return (the scaled reward the learner would otherwise see)
and the paired return. A policy-gradient learner estimates the value of a change from such
returns: their spread over seeds is the noise it has to average away.

Usage: ``python benchmarks/paired_reward.py [--episodes 20] [--preset steady] [--markdown FILE]``
"""

from __future__ import annotations

import argparse
from pathlib import Path

import gymnasium as gym
import numpy as np

import lawn_env
from agents import make_policy
from training.paired import PairedReward
from evaluation.seeds import VALIDATION_SEED_BASE

#: learner -> (the policy and its settings, or None for the interface's zero action)
LEARNERS: dict[str, tuple[str, dict[str, float]] | None] = {
    "zero action": None, "dv-mpc, 1.4 m grid": ("dv-mpc", {"drone_spacing_m": 1.4}), "rg-mpc": ("rg-mpc", {})}
#: the RL interface with the benchmark's actions and observations, for the expert learners
EXPERT_INTERFACE = {"base": "rl", "action_scheme": "direct", "obs_clip": None}


def returns(preset: str, seeds: list[int], anchor: str, learner: str) -> tuple[np.ndarray, np.ndarray]:
    """The env's own and the paired return of ``learner``'s episode on each seed."""
    spec = LEARNERS[learner]
    env = PairedReward(gym.make("lawn/Joint-v1", config=preset, interface="rl" if spec is None else EXPERT_INTERFACE),
                       anchor=anchor)
    policy = None if spec is None else make_policy(spec[0], env.unwrapped.config, **spec[1])
    zero = np.zeros(env.action_space.shape, dtype=env.action_space.dtype)
    own, paired = [], []
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        if policy is not None:
            policy.reset(seed)
        total_own = total_paired = 0.0
        done = False
        while not done:
            obs, reward, terminated, truncated, info = env.step(zero if policy is None else policy.act(obs))
            total_paired += float(reward)
            total_own += float(env.unwrapped.interface.rewards_from_costs(np.array(info["stage_cost"])))
            done = terminated or truncated
        own.append(total_own)
        paired.append(total_paired)
    return np.array(own), np.array(paired)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--preset", nargs="+", default=["steady", "steady-low-power"])
    parser.add_argument("--anchor", default="dv-mpc")
    parser.add_argument("--markdown", type=Path)
    args = parser.parse_args(argv)
    seeds = list(range(VALIDATION_SEED_BASE, VALIDATION_SEED_BASE + args.episodes))
    lines = [(f"Learners on `lawn/Joint-v1` (RL interface), reward paired against `{args.anchor}`; "
              f"{args.episodes} validation seeds ({seeds[0]}-{seeds[-1]}), one full episode each; returns in reward "
              "units (the scaled cost, 120 slots), mean ± std over seeds:"), "",
             "| task | learner | return, env's reward | return, paired | spread removed (std ratio) |",
             "|---|---|---|---|---|"]
    for preset in args.preset:
        lawn_env.resolve_config(preset)  # an unknown preset is an error before any episode
        for learner in LEARNERS:
            own, paired = returns(preset, seeds, args.anchor, learner)
            s_own, s_paired = own.std(ddof=1), paired.std(ddof=1)
            lines.append(f"| {preset} | {learner} | {own.mean():.2f} ± {s_own:.2f} | {paired.mean():+.2f} ± "
                         f"{s_paired:.2f} | {s_own / s_paired:.1f}x |")
    lines += ["", ("A negative paired return: the learner costs more than the anchor on those seeds; a ratio "
              "above 1x: pairing removes spread (the luck the learner and the anchor share), below 1x: it adds "
              "the anchor's own failures.")]
    text = "\n".join(lines)
    print(text)
    if args.markdown:
        args.markdown.parent.mkdir(parents=True, exist_ok=True)
        args.markdown.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
