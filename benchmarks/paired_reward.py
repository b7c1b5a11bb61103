"""What the paired reward (agents.paired) does to the returns a learner sees: their spread over
seeds with and without pairing, for a learner at its start.

The learner is the RL interface's zero action on ``lawn/Joint-v1`` (``interface="rl"``: the
anchored scheme, the stake prior, the MPC's increments), the policy an RL run on the steady
tasks starts from; the anchor is ``dv-mpc``. Each validation seed plays one full episode of the
learner with the reward paired against the anchor, and records both the env's own return (the
scaled reward the learner would otherwise see) and the paired return. A policy-gradient learner
estimates the value of a change from such returns: their spread over seeds is the noise it has to
average away, and their standard error over the seeds the precision one batch of episodes gives.

Usage: ``python benchmarks/paired_reward.py [--episodes 20] [--preset steady] [--markdown FILE]``
"""

from __future__ import annotations

import argparse
from pathlib import Path

import gymnasium as gym
import numpy as np

import lawn_env
from agents.paired import PairedReward
from training.protocol import VALIDATION_SEED_BASE


def returns(preset: str, seeds: list[int], anchor: str) -> tuple[np.ndarray, np.ndarray]:
    """The env's own and the paired return of the zero action's episode on each seed."""
    env = PairedReward(gym.make("lawn/Joint-v1", config=preset, interface="rl"), anchor=anchor)
    zero = np.zeros(env.action_space.shape, dtype=env.action_space.dtype)
    own, paired = [], []
    for seed in seeds:
        env.reset(seed=seed)
        total_own = total_paired = 0.0
        done = False
        while not done:
            _, reward, terminated, truncated, info = env.step(zero)
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
    lines = [(f"The RL interface's zero action on `lawn/Joint-v1`, reward paired against `{args.anchor}`; "
             f"{args.episodes} validation seeds ({seeds[0]}-{seeds[-1]}), one full episode each; returns in reward "
             "units (the scaled cost, 120 slots):"), "",
             "| task | return, env's reward | return, paired | spread over seeds (std), env's / paired | ratio |",
             "|---|---|---|---|---|"]
    for preset in args.preset:
        lawn_env.resolve_config(preset)  # an unknown preset is an error before any episode
        own, paired = returns(preset, seeds, args.anchor)
        s_own, s_paired = own.std(ddof=1), paired.std(ddof=1)
        lines.append(f"| {preset} | {own.mean():.2f} ± {s_own:.2f} | {paired.mean():+.2f} ± {s_paired:.2f} | "
                     f"{s_own:.2f} / {s_paired:.2f} | {s_own / s_paired:.1f}x |")
    lines += ["", ("A negative paired return: the zero action costs more than the anchor on those seeds. "
              "The spread is what pairing removes: the luck the learner and the anchor share on the same seed.")]
    text = "\n".join(lines)
    print(text)
    if args.markdown:
        args.markdown.parent.mkdir(parents=True, exist_ok=True)
        args.markdown.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
