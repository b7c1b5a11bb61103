"""Training throughput of SB3 PPO on the lawn environments beside SB3 PPO on CartPole-v1.

Same algorithm settings for all (SB3's PPO defaults: MlpPolicy 64x64, n_steps 2048, one
environment, no normalization), one torch thread, the same run; the figure is environment steps
per second of wall time over ``--timesteps`` steps (best of ``--repeats``), model construction
excluded. Target (issue #5): lawn/Joint-v0 trains at least half as fast as CartPole-v1. The RL
interface ids (anchored actions: the MPC runs inside Joint as well) are timed beside them.

Usage: ``python benchmarks/train_throughput.py [--timesteps 10240] [--repeats 2]``
"""

from __future__ import annotations

import argparse
import platform
import sys
import time

import gymnasium as gym

import lawn_env  # noqa: F401


def measure(env_id: str, timesteps: int, repeats: int) -> float:
    import torch
    from stable_baselines3 import PPO

    torch.set_num_threads(1)
    best = 0.0
    for r in range(repeats):
        model = PPO("MlpPolicy", gym.make(env_id), seed=r, verbose=0, device="cpu")
        start = time.perf_counter()
        model.learn(total_timesteps=timesteps)
        best = max(best, timesteps / (time.perf_counter() - start))
    return best


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--timesteps", type=int, default=10240)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--markdown", help="also write the README's table of this run to this file")
    args = parser.parse_args(argv)
    import stable_baselines3
    import torch

    print(f"python {platform.python_version()}, torch {torch.__version__}, stable-baselines3 "
          f"{stable_baselines3.__version__}, one torch thread")
    rates = {env_id: measure(env_id, args.timesteps, args.repeats)
             for env_id in ("CartPole-v1", "lawn/Joint-v0", "lawn/Comm-v0", "lawn/JointRL-v0", "lawn/CommRL-v0")}
    base = rates["CartPole-v1"]
    print(f"{'env':<16}{'PPO steps/s':>14}{'vs CartPole':>13}")
    for env_id, rate in rates.items():
        print(f"{env_id:<16}{rate:>14,.0f}{rate / base:>12.2f}x")
    ok = rates["lawn/Joint-v0"] >= 0.5 * base
    print(f"[{'PASS' if ok else 'FAIL'}] lawn/Joint-v0 PPO throughput >= half of CartPole-v1's")
    if args.markdown:
        lines = [f"python {platform.python_version()}, torch {torch.__version__}, stable-baselines3 "
                 f"{stable_baselines3.__version__}, one torch thread:", "",
                 "| env | PPO steps/s | vs CartPole |", "|---|---|---|"]
        lines += [f"| {e} | {r:,.0f} | {r / base:.2f}× |" for e, r in rates.items()]
        lines += ["", f"* [{'PASS' if ok else 'FAIL'}] lawn/Joint-v0 PPO throughput >= half of CartPole-v1's"]
        with open(args.markdown, "w") as fh:
            fh.write("\n".join(lines) + "\n")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
