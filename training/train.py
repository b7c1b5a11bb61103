"""``lawn train``: runs of a :class:`~training.spec.TrainSpec` (:func:`train`, :func:`train_seeds`,
:func:`resume`) and the zoo's recipes (:func:`train_recipes`); the ``rl`` extra trains, this module
imports without it.

A run directory holds ``spec.json``, ``run.json``, ``config.json``, ``hyperparams.json`` (the file's
entry with the ``--hp`` overrides), the model (``model.zip``, ``vecnormalize.pkl``), the model selected
on the validation seeds (``best_model.zip``; ``learning_curve.csv``, :mod:`training.validation`), the
newest checkpoint (:mod:`training.callbacks`) and TensorBoard logs (``tb/``).
"""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path
from typing import Any

from agents.runs import AgentRecord, read_json, read_run
from evaluation.pool import pool_map
from evaluation.stats import mean_ci
from evaluation.sweep import execute

from .recipes import RECIPES, finished, recipe
from .spec import ALGORITHMS, TrainSpec, split_params
from .validation import RunSummary

__all__ = ["SeedsSummary", "train", "train_seeds", "resume", "train_recipes"]


# ---------------------------------------------------------------- runs
def train(spec: TrainSpec, callbacks: list[Any] | None = None) -> RunSummary:
    """Train the run of ``spec`` from scratch; returns its summary (also written to ``spec.out_dir``).
    ``callbacks`` are extra SB3 callbacks, run after the run's own (validation, checkpoints)."""
    if (spec.out_dir / "run.json").exists():
        raise ValueError(f"{spec.out_dir} already holds a run; use --resume {spec.out_dir} or another --out")
    params, version = spec.hyperparams()
    algorithm = ALGORITHMS[spec.algo]
    if algorithm.settings is not None:  # a trainer of its own (fleet, bc)
        summary: RunSummary = algorithm.load()(spec, params, version)
    else:
        from .sb3 import train_sb3  # here: this module imports without the rl extra

        summary = train_sb3(spec, params, split_params(spec.algo, spec.env_id, params), version, callbacks)
    spec.write()
    return summary


@dataclasses.dataclass(frozen=True)
class SeedsSummary:
    """A run per training seed (:func:`train_seeds`): each run's summary, in the order of the seeds, and
    the selected models' validation cost across seeds (its mean and 95 % half-width)."""

    algo: str
    env: str
    seeds: list[int]
    runs: list[RunSummary]
    best_validation_cost_mean: float
    best_validation_cost_ci95: float

    def as_json(self) -> dict[str, object]:
        """``seeds.json``: the fields, the runs' summaries, and each run's wall time and expert share."""
        return {"algo": self.algo, "env": self.env, "seeds": self.seeds, "runs": [r.as_json() for r in self.runs],
                "best_validation_cost_mean": self.best_validation_cost_mean,
                "best_validation_cost_ci95": self.best_validation_cost_ci95,
                "wall_time_s": [r.wall_time_s for r in self.runs], "expert_share": [r.expert_share for r in self.runs]}


def train_seeds(spec: TrainSpec, seeds: list[int], workers: int = 1, backend: str = "process") -> SeedsSummary:
    """Train ``spec`` once per seed into ``spec.out_dir/seed-<s>`` (``workers`` processes, or Ray, as
    ``lawn sweep``) and summarize the selected models' validation costs across seeds."""

    if len(set(seeds)) != len(seeds) or not seeds:
        raise ValueError(f"--seeds {seeds}: give one or more distinct seeds")
    progress = spec.progress and workers <= 1
    # absolute: a worker writes where this process means, whatever its own working directory
    specs = [dataclasses.replace(spec, seed=s, out_dir=(spec.out_dir / f"seed-{s}").absolute(), progress=progress)
             for s in seeds]
    summaries = sorted(execute(train, specs, workers, backend), key=lambda r: seeds.index(r.seed))
    unvalidated = [s.seed for s in summaries if s.best_validation_cost is None]
    if unvalidated:
        raise ValueError(f"seeds {unvalidated}: their runs recorded no validation, so there is no cost across seeds "
                         "(lawn_env.ENV_IDS validate; CartPole-v1 does not)")
    mean, half = mean_ci(float(s.best_validation_cost or 0.0) for s in summaries)
    result = SeedsSummary(spec.algo, spec.env_id, list(seeds), summaries, mean, half)
    (spec.out_dir / "seeds.json").write_text(json.dumps(result.as_json(), indent=2))
    return result


def resume(out_dir: Path, timesteps: int | None = None, progress: bool = True) -> RunSummary:
    """Continue an interrupted run from its last checkpoint up to its (or a new) timestep target, with
    the update count of an uninterrupted run, its history appended to the checkpoint's and an
    off-policy replay buffer restored; a run killed before its first checkpoint restarts from scratch."""
    from .callbacks import clear_history, latest_checkpoint, restore_history
    from .sb3 import learn, setup

    out_dir = Path(out_dir)
    run = read_run(out_dir, "--resume")
    record = run.record.as_json()
    trainer = record.get("trainer", record["algo"])
    if trainer not in ALGORITHMS or ALGORITHMS[trainer].settings is not None:
        raise ValueError(f"--resume {out_dir}: {trainer} runs are not resumable (no checkpoints); rerun lawn train")
    for key in ("algo", "env", "seed", "timesteps", "checkpoint_every", "eval_every", "eval_episodes"):
        if key not in record:
            raise ValueError(f"--resume {out_dir}: run.json has no {key!r} (not written by lawn train)")
    params = read_json(out_dir / "hyperparams.json", "--resume", "the run directory is incomplete")
    config = run.load_config("--resume", "the run directory is incomplete")
    target = int(record["timesteps"]) if timesteps is None else int(timesteps)
    checkpoint = latest_checkpoint(out_dir)
    done = int(record.get("num_timesteps") or 0)
    if done >= target and (out_dir / "model.zip").exists():
        raise ValueError(f"--resume {out_dir}: the run is finished ({done} steps, target {target}); "
                         f"pass --timesteps above {done} to train it further")
    if checkpoint is not None and checkpoint.steps >= target:
        raise ValueError(f"--resume {out_dir}: --timesteps {target} is not above the last checkpoint's "
                         f"{checkpoint.steps} steps")
    options = split_params(record["algo"], record["env"], params)  # before any file is touched
    record["timesteps"] = target
    record.pop("num_timesteps", None)
    if checkpoint is None and any((out_dir / "checkpoints").glob("model_*_steps.zip")):
        raise ValueError(f"--resume {out_dir}: its checkpoints (checkpoints/model_<N>_steps.zip) were written by an "
                         "older lawn, which checkpointed before the update; retrain the run")
    if checkpoint is None:  # killed before its first checkpoint: start over, cleanly
        clear_history(out_dir)
        record["wall_time_s"] = record["expert_decision_s"] = 0.0
    else:
        restore_history(out_dir, checkpoint)
        record["wall_time_s"] = float(checkpoint.state.get("wall_time_s", 0.0))
        record["expert_decision_s"] = float(checkpoint.state.get("expert_decision_s", 0.0))
    (out_dir / "run.json").write_text(json.dumps(record, indent=2))
    summary = learn(setup(AgentRecord.model_validate(record), options, config, out_dir, checkpoint), progress=progress)
    return dataclasses.replace(summary, resumed_from=checkpoint.steps if checkpoint is not None else None)


def train_recipes(runs: Path, names: list[str] | None = None, workers: int = 2, progress: bool = True) -> list[Path]:
    """``lawn zoo train``: the missing runs of the chosen recipes of :data:`training.recipes.RECIPES`
    (all by default; a recipe that starts from another in a second phase); returns the run directories."""
    runs = Path(runs)
    chosen = [recipe(n) for n in names] if names else list(RECIPES.values())
    done: list[Path] = []
    for phase in (False, True):
        specs = []
        for r in chosen:
            if bool(r.init_from) != phase:
                continue
            for s in r.seeds:
                out = runs / r.name / f"seed-{s}"
                done.append(out)
                if finished(out, r.timesteps):
                    continue
                if out.exists():
                    shutil.rmtree(out)  # an unfinished run: start it again from scratch
                specs.append(r.spec(runs, s))
        pool_map(train, specs, workers, progress, desc="training runs")
    return done
