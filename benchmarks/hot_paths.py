"""Time the hot paths of the tree it runs in: env steps, vector steps and the experts' decisions.

Made to be run side by side with another commit (two checkouts, interleaved runs, the ratios
quoted): each figure is the median over ``--repeats`` timed runs of a fixed, seeded workload, in
CPU seconds of this (single-threaded) process, which a busy host's other work does not inflate as
it does wall time; ``--json`` writes them for the comparison. The workloads:

* ``joint-step``, ``comm-step``: ``lawn/Joint-v1`` (zero action) and ``lawn/Comm-v1`` (its MPC's QPs
  every step) at K = 4, one env, microseconds per step;
* ``core-step``: the slot of ``joint-step`` alone (``lawn_env.core.step`` on a fixed state, decisions
  and draws), microseconds: the compiled kernel's call, without the env around it;
* ``joint-vector``, ``comm-vector``: the native vector envs at N = 256, microseconds per vector step;
* ``rg-mpc``, ``dv-mpc``: one decision of each expert on the default task, milliseconds.

Usage: ``python benchmarks/hot_paths.py [--repeats 5] [--json out.json]``
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

import gymnasium as gym
import numpy as np

import lawn_env

# the current ids of the tree this runs in (side_by_side.py runs it in an older checkout too, whose
# ids may carry an earlier version)
JOINT, COMM = (next(i for i in lawn_env.ENV_IDS if i.startswith(f"lawn/{name}-")) for name in ("Joint", "Comm"))


def _time(fn, calls: int, repeats: int) -> float:
    """Median CPU seconds per call of ``fn`` over ``repeats`` runs of ``calls`` calls (one warm-up run)."""
    fn(calls)
    runs = []
    for _ in range(repeats):
        start = time.process_time()
        fn(calls)
        runs.append((time.process_time() - start) / calls)
    return statistics.median(runs)


def _env_steps(env_id: str):
    env = gym.make(env_id).unwrapped
    action = np.zeros(env.action_space.shape, dtype=env.action_space.dtype)

    def run(calls: int) -> None:
        env.reset(seed=0)
        for _ in range(calls):
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset()
    return run


def _core_steps():
    from lawn_env import core

    env = gym.make(JOINT).unwrapped
    env.reset(seed=0)
    engine = env.engine
    action = engine.check(np.zeros(env.action_space.shape, dtype=env.action_space.dtype), batch=False)[None]
    decisions, _ = engine.decide(action)
    sim = engine.sim
    draws = sim.draw(np.random.default_rng(0))

    def run(calls: int) -> None:
        for _ in range(calls):
            core.step(sim.params, sim.state, decisions, draws)
    return run


def _vector_steps(env_id: str, num_envs: int):
    envs = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point")
    actions = np.zeros(envs.action_space.shape, dtype=envs.action_space.dtype)

    def run(calls: int) -> None:
        envs.reset(seed=0)
        for _ in range(calls):
            envs.step(actions)
    return run


def _decisions(policy_name: str):
    from agents import make_policy

    env = gym.make(JOINT).unwrapped
    policy = make_policy(policy_name, config=env.config)
    obs, _ = env.reset(seed=0)

    def run(calls: int) -> None:
        policy.reset()
        for _ in range(calls):
            policy.act(obs)
    return run


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--json", help="also write the figures to this JSON file")
    args = parser.parse_args(argv)
    figures = {
        "joint-step (us)": 1e6 * _time(_env_steps(JOINT), 4000, args.repeats),
        "core-step (us)": 1e6 * _time(_core_steps(), 8000, args.repeats),
        "comm-step (us)": 1e6 * _time(_env_steps(COMM), 1000, args.repeats),
        "joint-vector N=256 (us)": 1e6 * _time(_vector_steps(JOINT, 256), 200, args.repeats),
        "comm-vector N=256 (us)": 1e6 * _time(_vector_steps(COMM, 256), 40, args.repeats),
        "rg-mpc decision (ms)": 1e3 * _time(_decisions("rg-mpc"), 40, args.repeats),
        "dv-mpc decision (ms)": 1e3 * _time(_decisions("dv-mpc"), 40, args.repeats),
    }
    for name, value in figures.items():
        print(f"{name:<28}{value:>12.2f}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(figures, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
