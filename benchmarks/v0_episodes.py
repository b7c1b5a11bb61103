"""Every v0 episode bitwise as before: a digest of recorded episodes, compared with another tree.

Each case plays seeded episodes of a registered id (single, vector and PettingZoo views; v0 and RL
interfaces; fixed and random paths; the disturbance mode; the experts deciding) and hashes every
observation, reward, termination flag and info array it returns (SHA-256 of the raw bytes, in
order). The same cases run in a fresh process on ``--before``, a ``git worktree`` of the commit
before a change (made when missing), and every digest must be equal but for the changes the
environments' version histories record (:data:`DOCUMENTED_CHANGES`).

Usage: ``python benchmarks/v0_episodes.py [--before ../before-equations] [--before-commit SHA] [--slots 40]
[--markdown out.md]``
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from report import finish, worktree  # benchmarks/report.py, beside this script

HERE = Path(__file__).resolve().parents[1]
#: The commit before the equations-once refactor (every equation in one function).
BEFORE_COMMIT = "f10c390"
_MEASURED = "the Comm MPC plans from the measured state (lawn/Comm-v0's version history)"
#: Cases whose episodes a documented change moved since BEFORE_COMMIT: case -> why.
DOCUMENTED_CHANGES = {"comm-disturbed": _MEASURED, "comm-rl-disturbed": _MEASURED, "comm-rl-vector": _MEASURED}

#: name -> (id, keyword arguments of the env, view, decider): view "single", "vector" (N = 3) or
#: "parallel"; decider "random" (seeded uniform actions) or an expert's name.
CASES = {
    "joint": ("lawn/Joint-v0", {}, "single", "random"),
    "comm": ("lawn/Comm-v0", {}, "single", "random"),
    "joint-rl": ("lawn/JointRL-v0", {}, "single", "random"),
    "comm-rl": ("lawn/CommRL-v0", {}, "single", "random"),
    "joint-k3": ("lawn/Joint-v0", {"config": "k3"}, "single", "random"),
    "joint-k8-random-paths": ("lawn/Joint-v0", {"config": "k8"}, "single", "random"),
    "joint-disturbed": ("lawn/Joint-v0", {"config": "disturbed"}, "single", "random"),
    "comm-disturbed": ("lawn/Comm-v0", {"config": "disturbed"}, "single", "random"),
    "comm-rl-disturbed": ("lawn/CommRL-v0", {"config": "disturbed"}, "single", "random"),
    "comm-rl-disturbed-exact-measurements": ("lawn/CommRL-v0", {"config": "disturbed", "disturbance": {
        "measurement_noise_position_m": 0.0, "measurement_noise_velocity_mps": 0.0}}, "single", "random"),
    "joint-rl-lqr": ("lawn/Joint-v0", {"interface": {"base": "rl", "increment_anchor": "lqr"}}, "single", "random"),
    "joint-vector": ("lawn/Joint-v0", {"config": "disturbed"}, "vector", "random"),
    "comm-vector": ("lawn/Comm-v0", {}, "vector", "random"),
    "comm-rl-vector": ("lawn/CommRL-v0", {"config": "disturbed"}, "vector", "random"),
    "parallel": ("lawn/Parallel-v0", {}, "parallel", "random"),
    "joint-rg-mpc": ("lawn/Joint-v0", {}, "single", "rg-mpc"),
    "joint-ao-mpc-k3": ("lawn/Joint-v0", {"config": "k3"}, "single", "ao-mpc"),
    "comm-epa-steady": ("lawn/Comm-v0", {"config": "steady"}, "single", "epa"),
}


class Digest:
    def __init__(self):
        self.hash = hashlib.sha256()

    def add(self, value) -> None:
        if isinstance(value, dict):
            for key in sorted(value):
                self.hash.update(str(key).encode())
                self.add(value[key])
        elif isinstance(value, (list, tuple)):
            for v in value:
                self.add(v)
        elif isinstance(value, np.ndarray) and value.dtype == object:  # e.g. a vector env's episode_metrics
            self.hash.update(str(value.shape).encode())
            for v in value.ravel():
                self.add(v)
        elif value is None or isinstance(value, str):
            self.hash.update(repr(value).encode())
        else:
            a = np.asarray(value)
            self.hash.update(str(a.dtype).encode() + str(a.shape).encode())
            self.hash.update(np.ascontiguousarray(a).tobytes())


def _single(env_id: str, kwargs: dict, decider: str, slots: int, digest: Digest) -> None:
    import gymnasium as gym

    env = gym.make(env_id, **kwargs)
    policy = None
    if decider != "random":
        from agents import make_policy

        policy = make_policy(decider, env.unwrapped.config, env_id=env_id)
    for seed in (3, 4):
        rng = np.random.default_rng(seed)
        obs, info = env.reset(seed=seed)
        if policy is not None:
            policy.reset(seed=seed)
        digest.add([obs, info])
        for _ in range(slots):
            action = (rng.uniform(-1, 1, env.action_space.shape).astype(np.float32) if policy is None
                      else policy.act(obs))
            obs, reward, terminated, truncated, info = env.step(action)
            digest.add([obs, reward, terminated, truncated, info])
            if terminated or truncated:
                break
    env.close()


def _vector(env_id: str, kwargs: dict, slots: int, digest: Digest) -> None:
    import gymnasium as gym

    envs = gym.make_vec(env_id, num_envs=3, vectorization_mode="vector_entry_point", **kwargs)
    rng = np.random.default_rng(5)
    digest.add(list(envs.reset(seed=5)))
    for _ in range(2 * slots):
        digest.add(list(envs.step(rng.uniform(-1, 1, envs.action_space.shape).astype(np.float32))))
    envs.close()


def _parallel(kwargs: dict, slots: int, digest: Digest) -> None:
    import lawn_env

    env = lawn_env.parallel_env(**kwargs)
    rng = np.random.default_rng(6)
    digest.add(list(env.reset(seed=6)))
    for _ in range(slots):
        actions = {a: rng.uniform(-1, 1, env.action_space(a).shape).astype(np.float32) for a in env.agents}
        digest.add(list(env.step(actions)))
    env.close()


def digests(slots: int) -> dict[str, str]:
    import lawn_env  # noqa: F401  (registers the ids)

    out = {}
    for name, (env_id, kwargs, view, decider) in CASES.items():
        digest = Digest()
        if view == "single":
            _single(env_id, kwargs, decider, slots, digest)
        elif view == "vector":
            _vector(env_id, kwargs, slots, digest)
        else:
            _parallel(kwargs, slots, digest)
        out[name] = digest.hash.hexdigest()
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", type=Path, default=Path("../before-equations"),
                        help="the other tree (made with git worktree from --before-commit when missing)")
    parser.add_argument("--before-commit", default=BEFORE_COMMIT)
    parser.add_argument("--slots", type=int, default=40, help="slots per episode (default 40)")
    parser.add_argument("--markdown", help="write the table here")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(digests(args.slots)))
        return 0
    trees = {"this": HERE, "before": worktree(args.before, args.before_commit)}
    results = {}
    for label, tree in trees.items():
        env = dict(os.environ, PYTHONPATH=str(tree))
        out = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--child", "--slots", str(args.slots)],
                             env=env, cwd=tree, capture_output=True, text=True, check=True)
        results[label] = json.loads(out.stdout.strip().splitlines()[-1])
    lines = [f"{args.slots} slots per episode; before = {args.before_commit}.", "",
             "| case | id | view | decided by | bitwise as before |", "|---|---|---|---|---|"]
    different = []
    for name, (env_id, kwargs, view, decider) in CASES.items():
        same = results["this"][name] == results["before"][name]
        if not same:
            different.append(name)
        config = ", ".join([kwargs.get("config", "default")] + [f"{k}={v}" for k, v in kwargs.items() if k != "config"])
        verdict = "yes" if same else f"no: {DOCUMENTED_CHANGES.get(name, 'UNDOCUMENTED')}"
        lines.append(f"| {name} | `{env_id}` ({config}) | {view} | {decider} | {verdict} |")
    print("\n".join(lines))
    undocumented = [n for n in different if n not in DOCUMENTED_CHANGES]
    checks = [(f"{len(CASES) - len(different)} of {len(CASES)} cases bitwise as before; the others documented",
               not undocumented)]
    return finish(checks, args.markdown, lines)


if __name__ == "__main__":
    sys.exit(main())
