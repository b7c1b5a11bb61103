"""The distilled agents (the ``distil`` recipes of :mod:`training.recipes`: one fleet network
cloned from ``dv-mpc`` on the steady suite tasks) compared on those tasks, on two disjoint ranges of
test seeds (:func:`evaluation.stats.compare_ranges`), and shipped: ``lawn zoo build`` runs
:func:`evaluate_distil` for the page's ``zoo-distil`` block and :func:`export_distil`.

Each agent plays its own env with its own control law (``zoo:dv-comm``'s AGVs apply the delivery
law); the references ``dv-mpc`` and ``rg-mpc`` play ``lawn/Joint-v1`` of the same task on the same
seeds: the same scenario and draws, so the per-seed ratios compare realized control costs.
"""

from __future__ import annotations

import math
import shutil
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from agents.base import JOINT
from agents.learned import ZOO_DIR, export_agent, trained_config
from agents.runs import read_run
from evaluation.cells import fmt_num, fmt_paired, markdown_table
from evaluation.episode import Entry, EpisodeResult, Play
from evaluation.protocols import Batch, Protocol, execute
from evaluation.report import distil_table
from evaluation.run import policy_env
from evaluation.seeds import TEST_RANGES, test_seeds
from evaluation.stats import SCORE_HIGH, RangeComparison, compare_ranges, costs_of
from lawn_env import presets

from .recipes import RECIPES, Recipe, finished
from .validation import read_learning_curve, run_key, selected_at

__all__ = ["DISTIL_EPISODES", "own_law", "distil_protocol", "Distilled", "evaluate_distil", "export_distil"]

#: Test seeds per range and task.
DISTIL_EPISODES = 100
#: The clones' targets: the upper bound against rg-mpc below zero and against dv-mpc at most +3 % on
#: both ranges, and a decision in at most 1 ms (the median).
DISTIL_VS_RG, DISTIL_VS_DV, DISTIL_MS = 1.0, 1.03, 1.0


def distil_target(rg: RangeComparison, dv: RangeComparison, ms: float) -> str:
    """The verdict of the clones' targets (:data:`DISTIL_VS_RG`, :data:`DISTIL_VS_DV`, :data:`DISTIL_MS`)."""
    return "met" if rg.below(DISTIL_VS_RG - 1e-12) and dv.below(DISTIL_VS_DV) and ms <= DISTIL_MS else "missed"


def own_law(policy: str) -> dict[str, str]:
    """The control law ``policy`` (a learned agent, :func:`agents.learned.trained_config`) was trained
    with, as config settings."""
    return {"control.law": trained_config(policy).control.law}


def recipe_tasks(r: Recipe) -> list[str]:
    """The tasks a recipe of the section is compared on: those it trained on (``--hp tasks``), else its preset."""
    return list(r.hp.get("tasks") or [r.preset])


def distil_protocol(agents: Mapping[str, Sequence[str]], episodes: int = DISTIL_EPISODES) -> Protocol:
    """``dv-mpc`` and ``rg-mpc`` (on ``lawn/Joint-v1``) and every agent (``{policy: tasks}``, on its env,
    with its law) on each of its tasks, on the first ``episodes`` seeds of both test ranges."""
    seeds = tuple(test_seeds(episodes))
    batches = []
    for task in dict.fromkeys(t for tasks in agents.values() for t in tasks):
        config = presets.get(task)
        batches.append(Batch(task, config, (Entry(SCORE_HIGH, JOINT), Entry("rg-mpc", JOINT)), seeds))
        batches += [Batch(task, config.override(own_law(a)), (Entry(a, policy_env(a)),), seeds)
                    for a, tasks in agents.items() if task in tasks]
    return Protocol("distil", tuple(batches), {})


@dataclass
class Distilled:
    """The section's shipped runs (``{recipe: run dir}``, the validation-selected seed), their policy
    names, the episodes of :func:`distil_protocol` and the page block (tables and note)."""

    found: dict[str, Path]
    names: dict[str, str]
    rows: list[EpisodeResult]
    block: str
    episodes: int


def _finished(r: Recipe, runs: Path) -> list[Path]:
    return [runs / r.name / f"seed-{s}" for s in r.seeds if finished(runs / r.name / f"seed-{s}", r.timesteps)]


def _chosen(r: Recipe, runs: Path) -> Path | None:
    """The recipe's finished run with the lowest selected validation (None: no finished run)."""
    dirs = _finished(r, runs)
    if not dirs:
        return None
    keys = [run_key(d) for d in dirs]
    return dirs[int(np.argmin(keys))]


def evaluate_distil(runs: Path, workers: int = 2, progress: bool = True, episodes: int = DISTIL_EPISODES
                    ) -> Distilled:
    """The section's recipes: each one's validation-selected run compared on its tasks
    (:func:`distil_protocol`) and rendered (:func:`~evaluation.report.distil_table`; the RL runs'
    learning curves on the validation seeds beside it)."""
    section = {name: r for name, r in RECIPES.items() if r.section == "distil"}
    found = {name: d for name, r in section.items() if (d := _chosen(r, Path(runs))) is not None}
    if not found:
        raise ValueError(f"{runs}: no finished distil recipe runs ({', '.join(section)}; lawn zoo train --only ...)")
    names = {name: read_run(d).policy_name for name, d in found.items()}
    played = execute(distil_protocol({names[n]: recipe_tasks(section[n]) for n in found}, episodes),
                     Play(workers, progress))
    rows = played.results
    labels = {names[n]: (f"`zoo:{n}`", section[n].evaluated_on) for n in found}
    targeted = {names[n] for n in found if section[n].algo == "fleet"}  # the clones of dv-mpc

    def target(policy: str, rg: RangeComparison, dv: RangeComparison, ms: float) -> str:
        return distil_target(rg, dv, ms) if policy in targeted else "–"

    tasks = list(dict.fromkeys(t for n in found for t in recipe_tasks(section[n])))
    note = (f"{episodes} test seeds from each of {', '.join(map(str, TEST_RANGES))} per task. Trained by: "
            + "; ".join(f"`{section[n].command()}`" for n in found) + ".")
    curves = [_curve_table(n, d, d == found[n]) for n in found if section[n].algo != "fleet"
              for d in _finished(section[n], Path(runs))]
    block = "\n\n".join([distil_table(played.stats, labels, tasks, JOINT, target), note, *curves])
    return Distilled(found, names, rows, block, episodes)


def _curve_table(name: str, run_dir: Path, shipped: bool) -> str:
    """An RL run's learning curve: the validation cost and the paired change against its start."""
    rows = read_learning_curve(run_dir)
    body = [[f"{int(r['timesteps']):,}", fmt_num(r["control_cost"]), fmt_paired(r.get("vs_start", math.nan),
                                                                               r.get("vs_start_ci95", math.nan)),
             fmt_paired(r["vs_reference"], r["vs_reference_ci95"])] for r in rows]
    head = ["steps", "validation cost", "vs start (paired)", "vs rg-mpc (paired)"]
    record = read_run(run_dir).record
    wall = math.nan if record.wall_time_s is None else record.run_seconds
    return (f"`{name}` ({run_dir.name}{', shipped' if shipped else ''}; {wall / 60:.0f} min), learning curve on the "
            "validation seeds:\n\n" + markdown_table(head, body))


def export_distil(d: Distilled, target: Path = ZOO_DIR) -> list[Path]:
    """Each run of ``d`` as ``target/<recipe>``."""
    return [_export(name, run_dir, d.names[name], d, Path(target)) for name, run_dir in d.found.items()]


def _export(name: str, run_dir: Path, policy: str, d: Distilled, target: Path) -> Path:
    """``target/<name>``: the run's network with a record of how it compares on every task."""
    r, run = RECIPES[name], read_run(run_dir)
    env = r.evaluated_on
    per_task = {}
    for task in recipe_tasks(r):
        mine = costs_of(d.rows, policy, env, task)
        per_task[task] = {ref: [g.change for g in compare_ranges(mine, costs_of(d.rows, ref, JOINT, task)).ranges]
                          for ref in (SCORE_HIGH, "rg-mpc")}
    record = {"name": name, "label": r.label, "trained_on": r.env_id, "evaluated_on": env, "command": r.command(),
              "budget_steps": run.record.steps(r.timesteps), "training_seeds": list(r.seeds),
              "shipped_seed": run.record.require("seed"), "wall_time_s": [round(run.record.run_seconds, 1)],
              "selected_on": "lowest selected validation against rg-mpc on the validation seeds (500000 + i)",
              "selected_at_steps": selected_at(run_dir),
              "benchmark": {"test_seeds": " and ".join(f"{b}-{b + d.episodes - 1}" for b in TEST_RANGES),
                            "reference": SCORE_HIGH, "tasks": per_task}}
    out = Path(target) / name
    if out.exists():
        shutil.rmtree(out)
    return export_agent(run_dir, out, record)
