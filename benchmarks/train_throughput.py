"""Training throughput of SB3 PPO on the lawn environments beside SB3 PPO on CartPole-v1.

Same algorithm settings for all (SB3's PPO defaults: MlpPolicy 64x64, n_steps 2048, one
environment, no normalization), one torch thread, the same run; the figure is environment steps
per second of wall time over ``--timesteps`` steps (best of ``--repeats``), model construction
excluded. Target: lawn/Joint-v1 trains at least half as fast as CartPole-v1. The RL
interface ids (anchored actions: the MPC runs inside Joint as well) are timed beside them. Then
PPO on lawn/Joint-v1 with 64 envs, SB3's DummyVecEnv beside lawn's native vector env
(``lawn train --vec native``); target: the native path >= 10,000 steps/s on 2 cores.

Usage: ``python benchmarks/train_throughput.py [--timesteps 10240] [--repeats 2]``
"""

from __future__ import annotations

import argparse
import platform
import sys
import time

import gymnasium as gym
from report import marks  # benchmarks/report.py, beside this script

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


#: PPO settings of the N = 64 comparison (one rollout = 64 x 32 = 2,048 steps, as SB3's default).
VEC_PPO = {"n_steps": 32, "batch_size": 512, "n_epochs": 4}


def measure_vec(mode: str, n_envs: int, timesteps: int, repeats: int) -> float:
    """PPO env-steps per second on lawn/Joint-v1 (v0) with ``n_envs`` copies: SB3's DummyVecEnv of
    single envs (``mode="dummy"``) or lawn's batched vector env (``"native"``)."""
    import torch
    from stable_baselines3 import PPO

    from lawn_env import ScenarioConfig
    from training.sb3 import make_train_env

    torch.set_num_threads(1)
    best = 0.0
    for r in range(repeats):
        venv = make_train_env("lawn/Joint-v1", ScenarioConfig(), n_envs, r, False, None, interface="v0", vec=mode)
        model = PPO("MlpPolicy", venv, seed=r, verbose=0, device="cpu", **VEC_PPO)
        start = time.perf_counter()
        model.learn(total_timesteps=timesteps)
        best = max(best, timesteps / (time.perf_counter() - start))
        venv.close()
    return best


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--timesteps", type=int, default=10240)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--markdown", help="also write the README's table of this run to this file")
    parser.add_argument("--vec-timesteps", type=int, default=65536, help="steps of the N = 64 comparison")
    args = parser.parse_args(argv)
    import stable_baselines3
    import torch

    print(f"python {platform.python_version()}, torch {torch.__version__}, stable-baselines3 "
          f"{stable_baselines3.__version__}, one torch thread")
    rates = {env_id: measure(env_id, args.timesteps, args.repeats)
             for env_id in ("CartPole-v1", "lawn/Joint-v1", "lawn/Comm-v1", "lawn/JointRL-v1", "lawn/CommRL-v1")}
    base = rates["CartPole-v1"]
    print(f"{'env':<16}{'PPO steps/s':>14}{'vs CartPole':>13}")
    for env_id, rate in rates.items():
        print(f"{env_id:<16}{rate:>14,.0f}{rate / base:>12.2f}x")
    vec = {mode: measure_vec(mode, 64, args.vec_timesteps, args.repeats) for mode in ("dummy", "native")}
    print(f"PPO on lawn/Joint-v1, 64 envs ({VEC_PPO}): DummyVecEnv {vec['dummy']:,.0f} steps/s, "
          f"native vector env {vec['native']:,.0f} steps/s ({vec['native'] / vec['dummy']:.1f}x)")
    ok = rates["lawn/Joint-v1"] >= 0.5 * base
    ok_vec = vec["native"] >= 10_000
    targets = marks([], [("lawn/Joint-v1 PPO throughput >= half of CartPole-v1's", ok),
                         ("lawn/Joint-v1 PPO on the native vector env (N = 64) >= 10,000 steps/s", ok_vec)])
    print("\n".join(targets))
    if args.markdown:
        lines = [f"python {platform.python_version()}, torch {torch.__version__}, stable-baselines3 "
                 f"{stable_baselines3.__version__}, one torch thread:", "",
                 "| env | PPO steps/s | vs CartPole |", "|---|---|---|"]
        lines += [f"| {e} | {r:,.0f} | {r / base:.2f}× |" for e, r in rates.items()]
        lines += ["", "PPO on lawn/Joint-v1 (v0 interface), 64 envs, n_steps 32, batch 512, 4 epochs:", "",
                  "| vector env | PPO steps/s |", "|---|---|",
                  f"| SB3 DummyVecEnv of 64 single envs | {vec['dummy']:,.0f} |",
                  f"| lawn's native vector env (`--vec native`) | {vec['native']:,.0f} |"]
        lines += [""] + [f"* {mark}" for mark in targets]
        with open(args.markdown, "w") as fh:
            fh.write("\n".join(lines) + "\n")
    return 0  # speed targets are reported, never an error


if __name__ == "__main__":
    sys.exit(main())
