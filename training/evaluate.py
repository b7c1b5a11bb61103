"""Running policies on seeded episodes and summarizing the results.

One episode is one seed: ``env.reset(seed=s)`` and ``policy.reset(s)``, so every policy of a
comparison sees the same references, initial offsets and (for the same decisions) the same
fading. Episodes are independent; they run in a process pool when ``workers > 1`` and the rows
come back in seed order whatever the scheduling.
"""

from __future__ import annotations

import functools
import json
import math
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import gymnasium as gym
import numpy as np

import lawn_env
from agents import Policy, make_policy
from agents.rollouts import Step, rollout
from lawn_env import ScenarioConfig

from . import limits
from .pool import pool_map, worker_pool
from .tables import Geometric, fmt_geometric, mean_ci, paired_difference, paired_geometric, write_csv

__all__ = ["episode_row", "run_episode", "pool_map", "worker_pool", "evaluate", "summarize", "write_rows",
           "SUMMARY_METRICS", "TRANSIENT_SLOTS", "split_cost", "paired_cost_difference", "paired_cost_geometric"]

#: Where an episode's control cost splits (docs/benchmark.md, "The cost's structure"): slots
#: 0..TRANSIENT_SLOTS-1 are the transient (the AGVs' recovery from their initial offsets while the
#: drone flies in from the area's edge: 91 % of ``rg-mpc``'s cost on the default task falls in
#: slots 0-9), the slots from TRANSIENT_SLOTS on the sustained part. ``--transient-slots`` of
#: ``lawn evaluate`` and ``lawn benchmark`` moves it.
TRANSIENT_SLOTS = 20

#: Metrics summarized with a mean and a 95 % interval (name, label).
SUMMARY_METRICS = (
    ("control_cost", "control cost"),
    ("transient_cost", "transient cost"),
    ("sustained_cost", "sustained cost"),
    ("rmse_m", "RMSE (m)"),
    ("outage_rate", "outage rate"),
    ("decision_time_median_s", "decision time (s)"),
)


def episode_row(policy: Policy, env_id: str, config: ScenarioConfig, seed: int,
                transient_slots: int = TRANSIENT_SLOTS) -> dict:
    """One seeded, full episode of the unmodified scenario (``env_id`` of ``lawn_env.ENV_IDS``)
    under a built policy (:func:`agents.rollout`); returns a flat row of MODEL.md §6 metrics plus
    decision statistics and the control cost's transient and sustained parts (:func:`split_cost`)."""
    if env_id not in lawn_env.ENV_IDS:
        raise ValueError(f"unknown env id {env_id!r}; valid: {', '.join(lawn_env.ENV_IDS)}")
    ao_iterations, stage_costs = [], []
    fallbacks = 0

    def on_step(step: Step) -> None:
        nonlocal fallbacks
        plan = policy.last_plan
        if plan is not None:
            ao_iterations.append(plan.iterations)
            fallbacks += plan.info.get("qp_fallbacks", 0)
        fallbacks += int(step.info.get("mpc_fallbacks", 0))
        stage_costs.append(float(step.info["stage_cost"]))

    env = gym.make(env_id, config=config)
    episode = rollout(env, policy, seed, on_step=on_step)
    env.close()
    row = {"policy": policy.name, "env": env_id, "seed": seed}
    for key, value in episode.metrics.items():
        row[key] = json.dumps(value) if isinstance(value, list) else value
    row["decision_time_median_s"] = episode.decision_time_median_s
    row["decision_time_p95_s"] = float(np.percentile(episode.decision_s, 95))
    row["ao_iterations_mean"] = float(np.mean(ao_iterations)) if ao_iterations else math.nan
    row["qp_fallbacks"] = fallbacks
    row["transient_cost"], row["sustained_cost"] = split_cost(stage_costs, transient_slots)
    row["transient_slots"] = int(transient_slots)
    row["stage_costs"] = json.dumps(stage_costs)  # realized stage cost per slot (the per-slot figures read it)
    return row


def build_policy(policy: str, config: ScenarioConfig, env_id: str | None = None,
                 policy_kwargs: Mapping[str, Any] | None = None) -> tuple[Policy, ScenarioConfig]:
    """The policy a row name plays and the config it plays on: a limit or noise-floor row
    (:mod:`training.limits`) is an expert on its lifted config or with its settings; any other
    name is :func:`agents.make_policy` on ``config``."""
    name, played, kwargs = limits.resolve(policy, config, policy_kwargs)
    return make_policy(name, played, env_id=env_id, **kwargs), played


def run_episode(policy: str, env_id: str, config: ScenarioConfig, seed: int,
                policy_kwargs: Mapping[str, Any] | None = None, transient_slots: int = TRANSIENT_SLOTS) -> dict:
    """One seeded episode of the named policy or reference row (:func:`build_policy`,
    :func:`episode_row`)."""
    agent, played = build_policy(policy, config, env_id, policy_kwargs)
    row = episode_row(agent, env_id, played, seed, transient_slots)
    row["policy"] = policy
    return row


def _run_task(task, transient_slots: int = TRANSIENT_SLOTS) -> dict:
    return run_episode(*task, transient_slots=transient_slots)


def split_cost(stage_costs: Sequence[float], transient_slots: int = TRANSIENT_SLOTS) -> tuple[float, float]:
    """(transient, sustained) control cost of an episode's per-slot stage costs: the sums over slots
    ``0..transient_slots-1`` and ``transient_slots..``; they add up to the episode's control cost (an
    episode no longer than the split is all transient)."""
    if isinstance(transient_slots, bool) or not isinstance(transient_slots, (int, np.integer)) or transient_slots < 0:
        raise ValueError(f"transient_slots={transient_slots!r}: must be an integer >= 0")
    costs = np.asarray(stage_costs, dtype=float)
    return float(costs[:transient_slots].sum()), float(costs[transient_slots:].sum())


def evaluate(tasks: Iterable[tuple], workers: int = 1, progress: bool = True, desc: str = "episodes",
             transient_slots: int = TRANSIENT_SLOTS) -> list[dict]:
    """Run ``(policy, env_id, config, seed, policy_kwargs)`` tasks; rows in task order, each with its
    ``transient_cost`` and ``sustained_cost`` split at ``transient_slots`` (:func:`split_cost`)."""
    tasks = list(tasks)
    split_cost((), transient_slots)  # a bad split fails before any episode
    return pool_map(functools.partial(_run_task, transient_slots=transient_slots), tasks, workers, progress, desc)


def summarize(rows: list[dict], metrics: Sequence[tuple[str, str]] = SUMMARY_METRICS, by: str = "policy") -> list[dict]:
    """Mean and 95 % t-interval half-width of each metric per group, in first-seen group order."""
    groups: dict[str, list[dict]] = {}
    for row in rows:
        groups.setdefault(row[by], []).append(row)
    out = []
    for name, members in groups.items():
        entry = {by: name, "episodes": len(members)}
        for key, _ in metrics:
            entry[key], entry[f"{key}_ci95"] = mean_ci(float(r[key]) for r in members)
        out.append(entry)
    return out


def paired_cost_difference(rows: list[dict], reference: str, metric: str = "control_cost") -> dict[str, tuple[float, float]]:
    """Per policy: mean and 95 % t-interval half-width of the per-seed relative difference
    ``(x - x_ref) / x_ref`` against ``reference`` on the seeds both ran (a paired comparison,
    :func:`training.tables.paired_difference`)."""
    ref = {r["seed"]: float(r[metric]) for r in rows if r["policy"] == reference}
    out = {}
    for name in dict.fromkeys(r["policy"] for r in rows):
        mean, half, n = paired_difference({r["seed"]: float(r[metric]) for r in rows if r["policy"] == name}, ref)
        if n > 1:
            out[name] = (mean, half)
    return out


def paired_cost_geometric(rows: list[dict], reference: str, metric: str = "control_cost") -> dict[str, Geometric]:
    """Per policy: the geometric mean of its per-seed cost ratios against ``reference`` with a 95 %
    bootstrap interval and the share of seeds won (:func:`training.tables.paired_geometric`)."""
    ref = {r["seed"]: float(r[metric]) for r in rows if r["policy"] == reference}
    out = {}
    for name in dict.fromkeys(r["policy"] for r in rows):
        mine = {r["seed"]: float(r[metric]) for r in rows if r["policy"] == name}
        if name != reference and any(s in ref for s in mine):
            out[name] = paired_geometric(mine, ref)
    return out


def format_table(summary: list[dict], metrics: Sequence[tuple[str, str]] = SUMMARY_METRICS, by: str = "policy",
                 paired: dict[str, tuple[float, float]] | None = None, reference: str | None = None,
                 scores: Mapping[str, tuple] | None = None, geometric: Mapping[str, Geometric] | None = None) -> str:
    """A Markdown table: mean ± 95 % interval per metric (decision time in ms), optionally the
    normalized score (``scores``: policy -> :func:`training.score.normalized_score`), the paired
    relative cost difference against ``reference`` (``paired``: mean of per-seed relative
    differences, t-interval) and the geometric one (``geometric``: the deciding statistic,
    docs/benchmark.md)."""
    from .score import SCORE_VERSION, format_score

    header = [by, "episodes"] + [label.replace("(s)", "(ms)") for _, label in metrics]
    if scores:
        header.insert(3, f"score v{SCORE_VERSION} [95 %]")
    if paired:
        header.append(f"cost vs {reference} (paired)")
    if geometric:
        header.append(f"cost vs {reference} (geometric [95 %], seeds won)")
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for entry in summary:
        cells = [str(entry[by]), str(entry["episodes"])]
        for key, _ in metrics:
            scale = 1e3 if key.startswith("decision_time") else 1.0
            mean, half = entry[key] * scale, entry[f"{key}_ci95"] * scale
            cells.append(f"{_fmt(mean)} ± {_fmt(half)}")
        if scores:
            cells.insert(3, format_score(scores.get(entry[by])))
        if paired:
            mean, half = paired.get(entry[by], (math.nan, math.nan))
            cells.append("–" if entry[by] == reference else f"{mean * 100:+.1f} % ± {half * 100:.1f} %")
        if geometric:
            cells.append("–" if entry[by] == reference else fmt_geometric(geometric.get(entry[by])))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _fmt(x: float) -> str:
    if not math.isfinite(x):
        return "n/a"
    if x == 0 or 1e-2 <= abs(x) < 1e5:
        return f"{x:.4g}" if abs(x) < 10 else f"{x:,.1f}" if abs(x) < 1000 else f"{x:,.0f}"
    return f"{x:.3g}"


def write_rows(rows: list[dict], path: str | Path) -> Path:
    """Write rows as CSV or JSON, chosen by the file extension (``.csv`` or ``.json``)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".csv", ".json"):
        raise ValueError(f"--out {str(path)!r}: the extension must be .csv or .json, got {suffix or 'none'!r}")
    path.parent.mkdir(parents=True, exist_ok=True)
    if suffix == ".json":
        path.write_text(json.dumps(rows, indent=2))
    else:
        write_csv(rows, path)
    return path
