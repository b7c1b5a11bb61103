"""From-scratch PPO throughput: the shipped scratch recipes (``ppo-comm-scratch``, ``ppo-joint-scratch``
of ``training.recipes``) as this tree defines them, environment steps per second of ``model.learn``.

The env and the model are built as ``lawn train`` builds them for the recipe (its hyperparameters, its
interface, its vector env, its normalization), seed 0; the figure is ``--timesteps`` over the wall
time of ``model.learn`` alone (no validation, no checkpoint: those are a run's, not the learner's),
best of ``--repeats``. Run beside the commit before a change::

    python benchmarks/side_by_side.py --commit C --figures --repeats 3 -- python benchmarks/scratch_throughput.py

(a script new in this tree times the other tree's recipes). ``--threads`` sets torch's threads (1: as
``lawn train`` runs its seeds two side by side; 2: one run alone on both cores).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import tempfile
import time
from pathlib import Path

#: Steps timed per recipe: six rollouts of the RL-scale recipe (256 x 120), ninety of the one before (8 x 256).
TIMESTEPS = 184_320
RECIPES = ("ppo-comm-scratch", "ppo-joint-scratch")


def measure(name: str, timesteps: int, repeats: int, threads: int) -> float:
    import torch

    from agents.runs import algorithm_class
    from training.recipes import recipe
    from training.sb3 import make_train_env
    from training.spec import split_params

    r = recipe(name)
    best = 0.0
    for rep in range(repeats):
        with tempfile.TemporaryDirectory() as tmp:
            spec = dataclasses.replace(r.spec(Path(tmp), 0), timesteps=timesteps)
            params, _ = spec.hyperparams()
            options = split_params(spec.algo, spec.env_id, params)
            torch.set_num_threads(threads)
            env = make_train_env(spec.env_id, spec.config, options.n_envs, rep, options.normalize, None,
                                 interface=options.interface, vec=spec.vec)
            model = algorithm_class(spec.algo)(options.policy, env, seed=rep, verbose=0, device="cpu",
                                               **options.algo_kwargs)
            start = time.perf_counter()
            model.learn(total_timesteps=timesteps)
            best = max(best, model.num_timesteps / (time.perf_counter() - start))
            env.close()
    return best


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--timesteps", type=int, default=TIMESTEPS)
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--threads", type=int, default=1, help="torch threads (default: %(default)s)")
    parser.add_argument("--json", help="write the figures to this file (benchmarks/side_by_side.py --figures)")
    args = parser.parse_args(argv)
    figures = {f"{name} steps/s": measure(name, args.timesteps, args.repeats, args.threads) for name in RECIPES}
    for key, value in figures.items():
        print(f"{key:<32}{value:>10,.0f}")
    if args.json:
        Path(args.json).write_text(json.dumps(figures))
    return 0


if __name__ == "__main__":
    sys.exit(main())
