"""Stable-Baselines3 callbacks of ``lawn train`` (validation on the real objective, checkpoints at
rollout boundaries, actor warm-up) and the checkpoints a run resumes from.

A checkpoint is taken after the algorithm has trained on every step it collected (SB3 calls
``on_rollout_start`` after ``train()``), so a resumed run repeats no update and loses none. It is
``checkpoints/<steps>/``: the model, its normalization statistics, an off-policy replay buffer,
the validation-selected model and ``state.json`` (steps, updates, wall time, expert time, the byte length of
every history file), renamed into place; only the newest is kept. Resuming truncates the history
files to those lengths and appends from there.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypedDict

from stable_baselines3.common.callbacks import BaseCallback

from agents.learned import ObsNormalizer, SB3Policy, marl_policy
from agents.policies import attach_residual
from agents.timing import DecisionClock
from evaluation.seeds import VALIDATION_SEED_BASE
from lawn_env import PARALLEL_ENV_ID, ScenarioConfig, central_env_id
from lawn_env.interface import InterfaceLike

from .validation import (
    append_learning_curve,
    read_learning_curve,
    selected_validation,
    selection_of,
    validation_costs,
    validation_reference,
    validation_row,
)

__all__ = ["ControlCostValidation", "RunCheckpoint", "ActorWarmup", "Checkpoint", "latest_checkpoint",
           "write_checkpoint", "restore_history", "clear_history", "save_model"]

#: Files of a run directory that only ever grow (appended rows), relative to the run directory.
HISTORY_FILES = ("learning_curve.csv", "monitor/*.csv")
#: The validation-selected model, restored with its checkpoint.
BEST_FILES = ("best_model.zip", "best_vecnormalize.pkl")


class CheckpointState(TypedDict, total=False):
    """A checkpoint's ``state.json``: its steps and updates, the run's wall time and the expert's
    decision time so far, and the byte length of each history file then (:data:`HISTORY_FILES`)."""

    steps: int
    updates: int
    wall_time_s: float
    expert_decision_s: float
    history: dict[str, int]


@dataclass(frozen=True)
class Checkpoint:
    """One complete checkpoint directory."""

    path: Path
    steps: int
    state: CheckpointState

    def file(self, name: str) -> Path | None:
        """``name`` in the checkpoint; None where it was not saved (normalization statistics, a replay buffer)."""
        path = self.path / name
        return path if path.exists() else None


def save_model(model: Any, folder: Path, prefix: str = "") -> None:
    """``<prefix>model.zip`` and the normalization statistics ``<prefix>vecnormalize.pkl`` of a
    normalized env (a stale file removed otherwise)."""
    model.save(str(folder / f"{prefix}model.zip"))
    venv = model.get_vec_normalize_env()
    if venv is not None:
        venv.save(str(folder / f"{prefix}vecnormalize.pkl"))
    else:
        (folder / f"{prefix}vecnormalize.pkl").unlink(missing_ok=True)


def _history(out_dir: Path) -> dict[str, int]:
    return {path.relative_to(out_dir).as_posix(): path.stat().st_size
            for pattern in HISTORY_FILES for path in sorted(out_dir.glob(pattern))}


def write_checkpoint(out_dir: Path, model: Any, state: CheckpointState) -> Checkpoint:
    """Save ``model`` (with its statistics and replay buffer) and the run's history lengths as
    ``checkpoints/<steps>/``, atomically; older checkpoints are removed."""
    out_dir = Path(out_dir)
    root = out_dir / "checkpoints"
    root.mkdir(parents=True, exist_ok=True)
    steps = int(model.num_timesteps)
    tmp = root / f".tmp-{steps}"
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir()
    save_model(model, tmp)
    if getattr(model, "replay_buffer", None) is not None:
        model.save_replay_buffer(str(tmp / "replay_buffer.pkl"))
    for name in BEST_FILES:
        if (out_dir / name).exists():
            shutil.copy2(out_dir / name, tmp / name)
    state = {**state, "steps": steps, "updates": int(getattr(model, "_n_updates", 0)), "history": _history(out_dir)}
    (tmp / "state.json").write_text(json.dumps(state, indent=2))
    final = root / str(steps)
    shutil.rmtree(final, ignore_errors=True)
    os.replace(tmp, final)
    for other in (path for path in root.iterdir() if path != final):
        if other.is_dir():
            shutil.rmtree(other, ignore_errors=True)
        else:
            other.unlink()
    return Checkpoint(final, steps, state)


def latest_checkpoint(out_dir: Path) -> Checkpoint | None:
    """The newest complete checkpoint of a run directory, or None."""
    found = []
    for path in (Path(out_dir) / "checkpoints").glob("*/state.json"):
        if not path.parent.name.isdigit() or not (path.parent / "model.zip").exists():
            continue
        try:
            state = json.loads(path.read_text())
        except (OSError, ValueError):
            continue  # not complete: the rename makes this unlikely, but never trust it
        found.append(Checkpoint(path.parent, int(path.parent.name), state))
    return max(found, key=lambda c: c.steps) if found else None


def restore_history(out_dir: Path, checkpoint: Checkpoint) -> None:
    """Cut every history file back to its length at the checkpoint (dropping files started after
    it) and put back the validation-selected model of that moment."""
    out_dir = Path(out_dir)
    kept = checkpoint.state.get("history", {})
    for pattern in HISTORY_FILES:
        for path in out_dir.glob(pattern):
            size = kept.get(path.relative_to(out_dir).as_posix())
            if size is None:
                path.unlink()
            else:
                with open(path, "r+b") as fh:
                    fh.truncate(size)
    for name in BEST_FILES:
        saved = checkpoint.file(name)
        if saved is not None:
            shutil.copy2(saved, out_dir / name)
        else:
            (out_dir / name).unlink(missing_ok=True)


def clear_history(out_dir: Path) -> None:
    """Remove everything a run wrote while training (before a restart from scratch)."""
    out_dir = Path(out_dir)
    for pattern in HISTORY_FILES + BEST_FILES + ("model.zip", "vecnormalize.pkl", "learning_curve.png", "summary.md"):
        for path in out_dir.glob(pattern):
            path.unlink()
    for name in ("checkpoints", "tb"):
        shutil.rmtree(out_dir / name, ignore_errors=True)


def _next_mark(steps: int, every: int) -> int:
    """The first multiple of ``every`` above ``steps``: schedules on the step count, not on calls,
    so a resumed run keeps the uninterrupted run's schedule."""
    return (steps // every + 1) * every


class ControlCostValidation(BaseCallback):
    """Every ``every`` environment steps, run the current policy (deterministic, as ``sb3:DIR`` runs it)
    on ``episodes`` full episodes of the unmodified scenario with the validation seeds ``VALIDATION_SEED_BASE + i``;
    append its learning-curve row (:func:`~training.validation.validation_row`) and keep the model
    :func:`~training.validation.selected_validation` chooses as ``best_model.zip``. A fresh run is
    validated before its first step (its costs kept in ``validation_start.json``), so selection keeps
    the starting policy (the anchor, or the clone it fine-tunes) unless training beats it significantly."""

    def __init__(self, env_id: str, config: ScenarioConfig, interface: InterfaceLike, episodes: int, every: int,
                 out_dir: Path, residual: Mapping[str, Any] | None = None,
                 clock: DecisionClock | None = None):
        super().__init__(verbose=0)
        self.selection = selection_of(Path(out_dir))  # the rule the run's record names (relative unless chosen)
        self.env_id, self.config, self.interface, self.residual = env_id, config, interface, residual
        self.clock = clock  # the run's expert time: the residual's anchor decides on it
        self.episodes, self.every, self.out_dir = episodes, every, Path(out_dir)
        self._next = every
        self._reference: dict[int, float] | None = None
        rows = read_learning_curve(self.out_dir)  # a resumed run: keep its history and its start
        self._last = max((int(r["timesteps"]) for r in rows), default=-1)
        start = self.out_dir / "validation_start.json"
        self._start = {int(k): float(v) for k, v in json.loads(start.read_text()).items()} if start.exists() else None

    def _on_training_start(self) -> None:
        if self._last < 0:  # a fresh run validates its starting policy (a clone it fine-tunes, or its anchor)
            self._record()
        self._next = _next_mark(self.num_timesteps, self.every)

    def _policy(self) -> Any:
        normalizer = ObsNormalizer.from_vecnormalize(self.model.get_vec_normalize_env())
        if self.env_id == PARALLEL_ENV_ID:
            return marl_policy(self.model, self.config, self.interface, normalizer, None, "marl")
        return attach_residual(SB3Policy(self.model, self.config, self.env_id, self.interface, normalizer),
                               self.residual, self.clock)

    def validate(self, start: bool = False) -> dict[str, float]:
        """The learning-curve columns of the current policy; ``start``: it is the run's starting policy,
        which every later validation is paired against."""
        policy = self._policy()
        env_id = central_env_id(self.env_id)
        if self._reference is None:  # rg-mpc on the validation seeds, once per process (deterministic)
            self._reference = validation_reference(env_id, self.config, self.episodes, VALIDATION_SEED_BASE)
        costs = validation_costs(policy, env_id, self.config, self._reference)
        if start:
            self._start = costs
            (self.out_dir / "validation_start.json").write_text(json.dumps({str(k): v for k, v in costs.items()}))
        return validation_row(costs, self._reference, self._start)

    def _on_step(self) -> bool:
        if self.num_timesteps >= self._next:
            self._record()
            self._next = _next_mark(self.num_timesteps, self.every)
        return True

    def _on_training_end(self) -> None:
        if self.num_timesteps != self._last:
            self._record()

    def _record(self) -> None:
        row = self.validate(start=self._last < 0)
        self._last = self.num_timesteps
        append_learning_curve(self.out_dir, self.num_timesteps, row)
        self.logger.record("validation/control_cost", row["control_cost"])
        self.logger.record("validation/vs_reference", row["vs_reference"])
        best = selected_validation(read_learning_curve(self.out_dir), self.selection)
        if best is not None and best["timesteps"] == self.num_timesteps:
            save_model(self.model, self.out_dir, "best_")


class RunCheckpoint(BaseCallback):
    """A checkpoint (:func:`write_checkpoint`) at the first rollout boundary at least ``every``
    steps after the previous one, and one at the end of training; its ``state.json`` holds the
    run's wall time and its expert's decision time so far (``wall_time_before`` and
    ``expert_before`` this process, then the process's time and ``clock``'s)."""

    def __init__(self, out_dir: Path, every: int, wall_time_before: float = 0.0, clock: DecisionClock | None = None,
                 expert_before: float = 0.0):
        super().__init__(verbose=0)
        self.out_dir, self.every, self.wall_time_before = Path(out_dir), every, wall_time_before
        self.clock, self.expert_before = clock or DecisionClock(), expert_before
        self._next = every
        self._start = 0.0

    def _on_training_start(self) -> None:
        self._start = time.perf_counter()
        self._next = _next_mark(self.num_timesteps, self.every)

    def _save(self) -> None:
        write_checkpoint(self.out_dir, self.model,
                         {"wall_time_s": self.wall_time_before + time.perf_counter() - self._start,
                          "expert_decision_s": self.expert_before + self.clock.seconds})
        self._next = _next_mark(self.num_timesteps, self.every)

    def _on_rollout_start(self) -> None:  # after train(): every collected step has been learned from
        if self.num_timesteps >= self._next:
            self._save()

    def _on_step(self) -> bool:
        return True

    def _on_training_end(self) -> None:
        self._save()


class ActorWarmup(BaseCallback):
    """Critic warm-up for fine-tuning a cloned policy: the actor (policy network, action head,
    log-std) is frozen for the first ``steps`` environment steps, so PPO's first updates fit the
    value function to the clone instead of moving it with an untrained critic's advantages."""

    def __init__(self, steps: int):
        super().__init__(verbose=0)
        self.steps = steps
        self.frozen: list[Any] = []

    def _on_training_start(self) -> None:
        if self.num_timesteps >= self.steps:  # a resumed run past its warm-up
            return
        policy: Any = self.model.policy
        self.frozen = [*policy.action_net.parameters(), *policy.mlp_extractor.policy_net.parameters()]
        if getattr(policy, "log_std", None) is not None:
            self.frozen.append(policy.log_std)
        for p in self.frozen:
            p.requires_grad_(False)

    def _on_step(self) -> bool:
        if self.frozen and self.num_timesteps >= self.steps:
            for p in self.frozen:
                p.requires_grad_(True)
            self.frozen = []
        return True
