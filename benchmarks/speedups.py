"""Speed-ups of the compiled QP solver, measured side by side with the code before it.

Each measurement runs in a fresh process once per tree (this checkout and ``--before``, a
checkout of the commit before the change, made with ``git worktree add`` when missing), the two
trees interleaved, ``--repeats`` times; the figure is the median, and the ratio after/before is
what is reported (the machine's speed cancels out of it):

* ``comm-vector``: ``lawn/Comm-v0`` native vector env, K = 4, N = 1,024, env-steps/s, and as a
  multiple of Gymnasium's CartPoleVectorEnv (N = 1,024) timed in the same process;
* ``rl-vector``: ``lawn/JointRL-v0`` and ``lawn/CommRL-v0`` native vector envs, N = 64;
* ``experts``: median decision time of ``rg-mpc`` at K = 4 and K = 32 and ``ao-mpc`` at K = 4 on
  ``lawn/Joint-v0`` (seeded episodes, the same slots in both trees);
* ``ppo``: SB3 PPO on ``lawn/CommRL-v0`` with ``--vec native`` (N = 64), env-steps/s, and SB3's
  own update time (the floor the env cannot remove).

Targets: Comm-v0 vector >= 0.0075x CartPoleVectorEnv; the RL vector envs >= 5x before;
rg-mpc >= 3x faster at K = 4 and 32; ao-mpc >= 2x; PPO on CommRL-v0 >= 1.5x before.

Usage: ``python benchmarks/speedups.py [--before ../before] [--before-commit SHA] [--repeats 3]
[--only comm-vector rl-vector experts ppo] [--markdown out.md]``
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

from report import finish  # benchmarks/report.py, beside this script

HERE = Path(__file__).resolve().parents[1]
#: The commit before the compiled solver.
BEFORE_COMMIT = "9f88288"


# ---------------------------------------------------------------------- measurements (child side)
def _vector_rate(env_id: str, num_envs: int, steps: int, **kwargs) -> float:
    import gymnasium as gym

    envs = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", **kwargs)
    envs.action_space.seed(0)
    actions = [envs.action_space.sample() for _ in range(16)]
    envs.reset(seed=0)
    for i in range(3):  # compile and warm up
        envs.step(actions[i])
    envs.reset(seed=0)
    start = time.perf_counter()
    for i in range(steps):
        envs.step(actions[i % 16])
    rate = steps * num_envs / (time.perf_counter() - start)
    envs.close()
    return rate


def measure_comm_vector() -> dict:
    import lawn_env  # noqa: F401

    cart = _vector_rate("CartPole-v1", 1024, 500)
    comm = _vector_rate("lawn/Comm-v0", 1024, 65)
    return {"Comm-v0 vector N=1024 env-steps/s": comm, "CartPoleVectorEnv N=1024 env-steps/s": cart,
            "Comm-v0 vector / CartPoleVectorEnv": comm / cart}


def measure_rl_vector() -> dict:
    import lawn_env  # noqa: F401

    return {f"{e} vector N=64 env-steps/s": _vector_rate(f"lawn/{e}", 64, 130) for e in ("JointRL-v0", "CommRL-v0")}


def measure_experts() -> dict:
    import gymnasium as gym
    import numpy as np

    from agents import make_policy, rollout
    from lawn_env import ScenarioConfig

    out = {}
    for name, k, slots in (("rg-mpc", 4, 60), ("rg-mpc", 32, 12), ("ao-mpc", 4, 60)):
        config = ScenarioConfig(num_agvs=k)
        env = gym.make("lawn/Joint-v0", config=config)
        policy = make_policy(name, config)
        rollout(env, policy, seed=0, max_steps=2)  # compile and warm up
        times = []
        rollout(env, policy, seed=1, max_steps=slots, on_step=lambda step: times.append(step.decision_s))
        out[f"{name} K={k} median decision ms"] = 1e3 * float(np.median(times))
    return out


def measure_ppo() -> dict:
    import torch
    from stable_baselines3 import PPO

    from lawn_env import ScenarioConfig
    from training.train import make_train_env

    torch.set_num_threads(1)
    venv = make_train_env("lawn/CommRL-v0", ScenarioConfig(), 64, 0, False, None, interface="rl", vec="native")
    model = PPO("MlpPolicy", venv, seed=0, verbose=0, device="cpu", n_steps=32, batch_size=512, n_epochs=4)
    model.learn(total_timesteps=2048)  # compile and warm up
    steps = 16384
    start = time.perf_counter()
    model.learn(total_timesteps=steps, reset_num_timesteps=False)
    total = time.perf_counter() - start
    # SB3's own update cost: the same number of updates on the collected buffer, no env steps
    start = time.perf_counter()
    for _ in range(steps // 2048):
        model.train()
    update = time.perf_counter() - start
    venv.close()
    return {"PPO CommRL-v0 native N=64 env-steps/s": steps / total, "PPO update share of wall time": update / total}


MEASURES = {"comm-vector": measure_comm_vector, "rl-vector": measure_rl_vector, "experts": measure_experts,
            "ppo": measure_ppo}


# ---------------------------------------------------------------------- driver (parent side)
def _run(tree: Path, name: str) -> dict:
    env = dict(os.environ, PYTHONPATH=str(tree), OMP_NUM_THREADS="1")
    out = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--child", name], cwd=tree, env=env,
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _ensure_before(path: Path, commit: str) -> Path:
    if not (path / "lawn_env").is_dir():
        subprocess.run(["git", "-C", str(HERE), "worktree", "add", "--detach", str(path), commit], check=True,
                       capture_output=True)
    return path


TARGETS = {  # figure -> (kind, threshold): ratio after/before (higher is better) or absolute
    "Comm-v0 vector / CartPoleVectorEnv": ("absolute", 0.0075),
    "JointRL-v0 vector N=64 env-steps/s": ("ratio", 5.0),
    "CommRL-v0 vector N=64 env-steps/s": ("ratio", 5.0),
    "rg-mpc K=4 median decision ms": ("speedup", 3.0),
    "rg-mpc K=32 median decision ms": ("speedup", 3.0),
    "ao-mpc K=4 median decision ms": ("speedup", 2.0),
    "PPO CommRL-v0 native N=64 env-steps/s": ("ratio", 1.5),
}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--child", choices=list(MEASURES), help=argparse.SUPPRESS)
    parser.add_argument("--before", type=Path, default=HERE.parent / "before",
                        help="checkout of the code before the change (made with git worktree when missing)")
    parser.add_argument("--before-commit", default=BEFORE_COMMIT)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--only", nargs="+", choices=list(MEASURES), default=list(MEASURES))
    parser.add_argument("--markdown", help="also write the README's table of this run to this file")
    args = parser.parse_args(argv)
    if args.child:
        print(json.dumps(MEASURES[args.child]()))
        return 0
    before = _ensure_before(args.before.resolve(), args.before_commit)
    runs: dict[str, dict[str, list[float]]] = {"before": {}, "after": {}}
    for name in args.only:
        for _ in range(args.repeats):
            for label, tree in (("before", before), ("after", HERE)):  # interleaved
                for key, value in _run(tree, name).items():
                    runs[label].setdefault(key, []).append(value)
    rows, checks = [], []
    for key in runs["after"]:
        b, a = statistics.median(runs["before"][key]), statistics.median(runs["after"][key])
        ratio = a / b
        rows.append((key, b, a, ratio))
        kind, threshold = TARGETS.get(key, (None, None))
        if kind == "absolute":
            checks.append((f"{key} >= {threshold} (after: {a:.4f}; before: {b:.4f})", a >= threshold))
        elif kind == "ratio":
            checks.append((f"{key}: {ratio:.2f}x before (target >= {threshold}x)", ratio >= threshold))
        elif kind == "speedup":
            checks.append((f"{key}: {1 / ratio:.2f}x faster than before (target >= {threshold}x)", 1 / ratio >= threshold))
    head = f"medians of {args.repeats} interleaved runs per tree; before = {args.before_commit}"
    print(head)
    print(f"{'figure':<44}{'before':>14}{'after':>14}{'after/before':>14}")
    for key, b, a, r in rows:
        print(f"{key:<44}{b:>14,.4g}{a:>14,.4g}{r:>14.2f}")
    lines = [head + ":", "", "| figure | before | after | after / before |", "|---|---|---|---|"]
    lines += [f"| {k} | {b:,.4g} | {a:,.4g} | {r:.2f} |" for k, b, a, r in rows]
    return finish([], args.markdown, lines, targets=checks)  # speed targets: reported, never an error


if __name__ == "__main__":
    sys.exit(main())
