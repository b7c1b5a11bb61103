"""Measure ``env.step`` throughput of the lawn environments beside Gymnasium's CartPole-v1.

Unwrapped environments, pre-sampled actions, one core; each figure is the best of
``--repeats`` timed runs of ``--steps`` steps (resets between episodes are excluded from the
timing). Then the native vector envs at N = 1024 (``--num-envs``) beside Gymnasium's
CartPoleVectorEnv, resets included, and Joint-v1 at K = 32 with N = 256. Prints the tables and
checks its targets:

* ``lawn/Joint-v1`` at K = 4: at least 30,000 steps/s and within 4x of CartPole's step time;
* ``lawn/Comm-v1`` at K = 4: at least 3,000 steps/s;
* the native vector envs at N = 1024: Joint-v1 at K = 4 at least 1,000,000 env-steps/s and 0.1x
  CartPoleVectorEnv's, at K = 32 at least 150,000, Comm-v1 at least 100,000 at K = 4 (its
  compiled QP solver beside DAQP one QP at a time in the same run).

Usage: ``python benchmarks/env_throughput.py [--steps 20000] [--repeats 5] [--json out.json]``
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time

import gymnasium as gym
import numpy as np
from report import marks  # benchmarks/report.py, beside this script

import lawn_env  # noqa: F401  (registers the ids)


def measure(env_id: str, steps: int, repeats: int, seed: int = 0, **kwargs) -> float:
    env = gym.make(env_id, **kwargs).unwrapped
    env.action_space.seed(seed)
    actions = [env.action_space.sample() for _ in range(steps)]
    best = float("inf")
    for _ in range(repeats):
        env.reset(seed=seed)
        elapsed = 0.0
        i = 0
        while i < steps:
            start = time.perf_counter()
            done = False
            while i < steps and not done:
                _, _, terminated, truncated, _ = env.step(actions[i])
                done = terminated or truncated
                i += 1
            elapsed += time.perf_counter() - start
            if done:
                env.reset()
        best = min(best, elapsed)
    env.close()
    return steps / best


def measure_vector(env_id: str, num_envs: int, steps: int, repeats: int, seed: int = 0, **kwargs) -> float:
    """Env-steps per second of a native vector env (``vector_entry_point``): ``steps`` batched
    steps of ``num_envs`` envs, autoresets included, best of ``repeats``."""
    envs = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", **kwargs)
    envs.action_space.seed(seed)
    actions = [envs.action_space.sample() for _ in range(16)]
    best = float("inf")
    for _ in range(repeats):
        envs.reset(seed=seed)
        start = time.perf_counter()
        for i in range(steps):
            envs.step(actions[i % 16])
        best = min(best, time.perf_counter() - start)
    envs.close()
    return steps * num_envs / best


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=20000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--json", help="also write the figures to this JSON file")
    parser.add_argument("--markdown", help="also write the README's table of this run to this file")
    parser.add_argument("--num-envs", type=int, default=1024, help="envs of the native vector envs (default: 1024)")
    parser.add_argument("--vector-steps", type=int, default=240,
                        help="batched steps per timed vector run (default 240: two episodes, one reset wave)")
    parser.add_argument("--comm-vector-steps", type=int, default=130,
                        help="batched steps per timed Comm-v1 vector run (default 130: one reset wave)")
    args = parser.parse_args(argv)

    rows = []
    cartpole = measure("CartPole-v1", args.steps, args.repeats)
    rows.append(("CartPole-v1", "-", cartpole))
    for env_id in ("lawn/Joint-v1", "lawn/Comm-v1"):
        for k in (4, 32):
            steps = args.steps if (env_id == "lawn/Joint-v1" or k == 4) else max(args.steps // 10, 500)
            rows.append((env_id, k, measure(env_id, steps, args.repeats, num_agvs=k)))

    print(f"python {platform.python_version()}, numpy {np.__version__}, gymnasium {gym.__version__}, "
          f"{os.cpu_count()} cores, {platform.processor() or platform.machine()}")
    print(f"{'env':<16}{'K':>4}{'steps/s':>12}{'us/step':>10}{'x CartPole time':>17}")
    for env_id, k, rate in rows:
        print(f"{env_id:<16}{k!s:>4}{rate:>12,.0f}{1e6 / rate:>10.1f}{cartpole / rate:>17.1f}")

    n = args.num_envs
    vrep = min(args.repeats, 2)  # K = 32 draws random paths at every reset: minutes per run
    vrows = [("CartPoleVectorEnv", "-", measure_vector("CartPole-v1", n, args.vector_steps, vrep))]
    for k in (4, 32):
        vrows.append(("lawn/Joint-v1", k, measure_vector("lawn/Joint-v1", n, args.vector_steps, vrep, num_agvs=k)))
    small = max(n // 4, 1)  # K = 32 at a quarter of the envs (the second vector figure)
    vrows.append((f"lawn/Joint-v1 (N = {small})", 32,
                  measure_vector("lawn/Joint-v1", small, args.vector_steps, vrep, num_agvs=32)))
    # Comm-v1 solves N x K QPs per step: the compiled solver beside DAQP one QP at a time, same run
    for label, backend in (("lawn/Comm-v1", "compiled"), ("lawn/Comm-v1 (DAQP per QP)", "daqp")):
        vrows.append((label, 4, measure_vector("lawn/Comm-v1", n, args.comm_vector_steps, vrep, qp_backend=backend)))
    print(f"native vector envs, N = {n} (env-steps/s, resets included)")
    for env_id, k, rate in vrows:
        print(f"{env_id:<28}{k!s:>4}{rate:>14,.0f}{vrows[0][2] / rate:>10.1f}x CartPoleVectorEnv time")

    joint4 = next(r for e, k, r in rows if e == "lawn/Joint-v1" and k == 4)
    comm4 = next(r for e, k, r in rows if e == "lawn/Comm-v1" and k == 4)
    vector = {(label, k): rate for label, k, rate in vrows}  # the vector rows by label, not by position
    cartpole_vec, vjoint4, vjoint32 = vector["CartPoleVectorEnv", "-"], vector["lawn/Joint-v1", 4], vector["lawn/Joint-v1", 32]
    checks = [
        ("Joint-v1 K=4 >= 30,000 steps/s", joint4 >= 30000),
        ("Joint-v1 K=4 within 4x of CartPole step time", cartpole / joint4 <= 4.0),
        ("Comm-v1 K=4 >= 3,000 steps/s", comm4 >= 3000),
        (f"vector Joint-v1 K=4, N={n} >= 1,000,000 env-steps/s", vjoint4 >= 1e6),
        (f"vector Joint-v1 K=4, N={n} >= 0.1x CartPoleVectorEnv env-steps/s", vjoint4 >= 0.1 * cartpole_vec),
        (f"vector Joint-v1 K=32, N={n} >= 150,000 env-steps/s", vjoint32 >= 1.5e5),
        (f"vector Comm-v1 K=4, N={n} >= 100,000 env-steps/s", vector["lawn/Comm-v1", 4] >= 1e5),
    ]
    for mark in marks([], checks):  # speed targets: reported, never an error
        print(mark)
    if args.markdown:
        lines = [f"python {platform.python_version()}, numpy {np.__version__}, gymnasium {gym.__version__}, "
                 f"{os.cpu_count()} cores, {platform.machine()}:", "",
                 "| env | K | steps/s | µs/step | × CartPole step time |", "|---|---|---|---|---|"]
        lines += [f"| {e} | {'–' if k == '-' else k} | {r:,.0f} | {1e6 / r:.1f} | {cartpole / r:.1f} |" for e, k, r in rows]
        lines += ["", f"Native vector envs (`gym.make_vec(..., vectorization_mode=\"vector_entry_point\")`), "
                  f"N = {n}, resets included:", "",
                  "| env | K | env-steps/s | × CartPoleVectorEnv step time |", "|---|---|---|---|"]
        lines += [f"| {e} | {'–' if k == '-' else k} | {r:,.0f} | {vrows[0][2] / r:.1f} |" for e, k, r in vrows]
        lines += [""] + [f"* {mark}" for mark in marks([], checks)]
        with open(args.markdown, "w") as fh:
            fh.write("\n".join(lines) + "\n")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"rows": [{"env": e, "K": k, "steps_per_s": r} for e, k, r in rows],
                       "vector_rows": [{"env": e, "K": k, "num_envs": n, "env_steps_per_s": r} for e, k, r in vrows],
                       "checks": {n: ok for n, ok in checks}}, fh, indent=2)
    return 0  # speed targets are reported, never an error


if __name__ == "__main__":
    sys.exit(main())
