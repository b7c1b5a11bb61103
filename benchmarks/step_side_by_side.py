"""Nothing slower: the step and decision times of this tree beside another, interleaved.

Each measurement runs in a fresh process once per tree (this checkout and ``--before``, a
``git worktree`` of the commit before a change), the trees alternating, ``--repeats`` times; the
figure is the median per tree and the ratio this/before of the times is what is reported (the
machine's speed cancels out of it; below 1 is faster):

* ``joint-step``, ``comm-step``: one ``lawn/Joint-v0`` / ``lawn/Comm-v0`` step (seeded uniform
  actions, the env unwrapped), microseconds;
* ``joint-vector``, ``comm-vector``: one step of the native vector env at N = 1,024, milliseconds
  (``joint-vector-k32``: K = 32, random paths, the observation's windows computed in the loop);
* ``rg-mpc``: the median decision time of ``rg-mpc`` on ``lawn/Joint-v0`` (K = 4, one episode of
  40 slots), milliseconds.

The target: every ratio within 1.05.

Usage: ``python benchmarks/step_side_by_side.py [--before ../before-equations] [--before-commit SHA] [--repeats 5]
[--markdown out.md]`` (the worktree is made when missing; the default commit is the one before the
equations-once refactor).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from report import finish, worktree  # benchmarks/report.py, beside this script

HERE = Path(__file__).resolve().parents[1]
TARGET = 1.05
#: The commit before the equations-once refactor (every equation in one function).
BEFORE_COMMIT = "f10c390"


def _single(env_id: str, steps: int = 3000) -> float:
    import gymnasium as gym

    import lawn_env  # noqa: F401  (registers the ids)

    env = gym.make(env_id).unwrapped
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (64,) + env.action_space.shape).astype(np.float32)
    times = []
    env.reset(seed=0)
    for i in range(steps):
        start = time.perf_counter()
        *_, terminated, truncated, _ = env.step(actions[i % 64])
        times.append(time.perf_counter() - start)
        if terminated or truncated:
            env.reset(seed=i)
    return statistics.median(times[100:]) * 1e6


def _vector(env_id: str, steps: int = 60, **kwargs) -> float:
    import gymnasium as gym

    import lawn_env  # noqa: F401  (registers the ids)

    envs = gym.make_vec(env_id, num_envs=1024, vectorization_mode="vector_entry_point", **kwargs)
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (8,) + envs.action_space.shape).astype(np.float32)
    envs.reset(seed=0)
    for i in range(3):
        envs.step(actions[i])
    times = []
    for i in range(steps):
        start = time.perf_counter()
        envs.step(actions[i % 8])
        times.append(time.perf_counter() - start)
    return statistics.median(times) * 1e3


def _rg_mpc(slots: int = 40) -> float:
    import gymnasium as gym

    import lawn_env  # noqa: F401  (registers the ids)

    from agents import make_policy

    env = gym.make("lawn/Joint-v0")
    policy = make_policy("rg-mpc", env.unwrapped.config)
    obs, _ = env.reset(seed=0)
    policy.reset(seed=0)
    policy.act(obs)  # compile and warm up
    times = []
    for _ in range(slots):
        start = time.perf_counter()
        action = policy.act(obs)
        times.append(time.perf_counter() - start)
        obs, *_ = env.step(action)
    return statistics.median(times) * 1e3


MEASUREMENTS = {
    "joint-step": (lambda: _single("lawn/Joint-v0"), "us"),
    "comm-step": (lambda: _single("lawn/Comm-v0"), "us"),
    "joint-vector": (lambda: _vector("lawn/Joint-v0"), "ms"),
    "joint-vector-k32": (lambda: _vector("lawn/Joint-v0", steps=20, config="k32"), "ms"),
    "comm-vector": (lambda: _vector("lawn/Comm-v0"), "ms"),
    "rg-mpc": (_rg_mpc, "ms"),
}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", type=Path, default=Path("../before-equations"),
                        help="the other tree (made with git worktree from --before-commit when missing)")
    parser.add_argument("--before-commit", default=BEFORE_COMMIT)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--only", nargs="+", choices=list(MEASUREMENTS), default=list(MEASUREMENTS))
    parser.add_argument("--markdown", help="write the table here")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(MEASUREMENTS[args.child][0]()))
        return 0
    trees = {"this": HERE, "before": worktree(args.before, args.before_commit)}
    figures = {name: {label: [] for label in trees} for name in args.only}
    for _ in range(args.repeats):
        for name in args.only:
            for label, tree in trees.items():
                env = dict(os.environ, PYTHONPATH=str(tree))
                out = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--child", name], env=env,
                                     cwd=tree, capture_output=True, text=True, check=True)
                figures[name][label].append(json.loads(out.stdout.strip().splitlines()[-1]))
    lines = [f"Medians of {args.repeats} interleaved fresh-process runs per tree; before = {args.before_commit}.", "",
             "| measurement | this tree | before | ratio this/before |", "|---|---|---|---|"]
    checks = []
    for name in args.only:
        unit = MEASUREMENTS[name][1]
        mine = statistics.median(figures[name]["this"])
        other = statistics.median(figures[name]["before"])
        ratio = mine / other
        lines.append(f"| {name} | {mine:.3g} {unit} | {other:.3g} {unit} | {ratio:.3f} |")
        checks.append((f"{name}: {ratio:.3f} of before (target <= {TARGET})", ratio <= TARGET))
    print("\n".join(lines))
    return finish([], args.markdown, lines, targets=checks)  # speed targets: reported, never an error


if __name__ == "__main__":
    sys.exit(main())
