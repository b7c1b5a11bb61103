"""Checkpoints of ``lawn train`` runs: what is saved, where, and how a run resumes from one.

A checkpoint is taken at a rollout boundary, after the algorithm has trained on every step it
has collected (SB3 calls ``on_rollout_start`` after ``train()``), so a resumed run repeats no
update and loses none: it reaches the same step count with the same number of updates as an
uninterrupted run. One checkpoint is a directory ``checkpoints/<steps>/`` holding

==========================  ===================================================================
``model.zip``               the model (weights, optimizer state, step and update counters)
``vecnormalize.pkl``        the normalization statistics, when the run normalizes
``replay_buffer.pkl``       the replay buffer of an off-policy algorithm (SAC, TD3)
``best_model.zip``, ...     the validation-selected model as it stood at the checkpoint
``state.json``              steps, updates, wall time and the length in bytes of every history
                            file (``learning_curve.csv``, ``monitor/*.csv``) at that moment
==========================  ===================================================================

It is written to a temporary directory and renamed into place, so a kill while writing leaves
the previous checkpoint intact; only the newest complete checkpoint is kept. Resuming truncates
the history files to their checkpointed lengths (rows written after the checkpoint came from
steps the resumed run makes again) and appends from there.
"""

from __future__ import annotations

import json
import os
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["Checkpoint", "latest_checkpoint", "write_checkpoint", "restore_history", "clear_history",
           "HISTORY_FILES", "BEST_FILES"]

#: Files of a run directory that only ever grow (appended rows), relative to the run directory.
HISTORY_FILES = ("learning_curve.csv", "monitor/*.csv")
#: The validation-selected model, restored with its checkpoint.
BEST_FILES = ("best_model.zip", "best_vecnormalize.pkl")


@dataclass(frozen=True)
class Checkpoint:
    """One complete checkpoint directory."""

    path: Path
    steps: int
    state: dict

    @property
    def model(self) -> Path:
        return self.path / "model.zip"

    @property
    def vecnormalize(self) -> Path | None:
        path = self.path / "vecnormalize.pkl"
        return path if path.exists() else None

    @property
    def replay_buffer(self) -> Path | None:
        path = self.path / "replay_buffer.pkl"
        return path if path.exists() else None


def _history(out_dir: Path) -> dict[str, int]:
    sizes = {}
    for pattern in HISTORY_FILES:
        for path in sorted(out_dir.glob(pattern)):
            sizes[path.relative_to(out_dir).as_posix()] = path.stat().st_size
    return sizes


def write_checkpoint(out_dir: Path, model: Any, state: dict) -> Checkpoint:
    """Save ``model`` (and its normalization statistics and replay buffer) with the run's history
    lengths as ``checkpoints/<steps>/``, atomically; older checkpoints are removed."""
    out_dir = Path(out_dir)
    root = out_dir / "checkpoints"
    root.mkdir(parents=True, exist_ok=True)
    steps = int(model.num_timesteps)
    tmp = root / f".tmp-{steps}"
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir()
    model.save(str(tmp / "model.zip"))
    venv = model.get_vec_normalize_env()
    if venv is not None:
        venv.save(str(tmp / "vecnormalize.pkl"))
    if getattr(model, "replay_buffer", None) is not None:
        model.save_replay_buffer(str(tmp / "replay_buffer.pkl"))
    for name in BEST_FILES:
        if (out_dir / name).exists():
            shutil.copy2(out_dir / name, tmp / name)
    state = dict(state, steps=steps, updates=int(getattr(model, "_n_updates", 0)), history=_history(out_dir))
    (tmp / "state.json").write_text(json.dumps(state, indent=2))
    final = root / str(steps)
    if final.exists():
        shutil.rmtree(final)
    os.replace(tmp, final)
    for other in root.iterdir():
        if other == final:
            continue
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
        saved = checkpoint.path / name
        if saved.exists():
            shutil.copy2(saved, out_dir / name)
        elif (out_dir / name).exists():
            (out_dir / name).unlink()


def clear_history(out_dir: Path) -> None:
    """Remove everything a run wrote while training (before a restart from scratch)."""
    out_dir = Path(out_dir)
    for pattern in HISTORY_FILES + BEST_FILES + ("model.zip", "vecnormalize.pkl", "learning_curve.png", "summary.md"):
        for path in out_dir.glob(pattern):
            path.unlink()
    for name in ("checkpoints", "tb"):
        shutil.rmtree(out_dir / name, ignore_errors=True)
