"""Playing policies on seeded episodes: (policy, env, config, seed) to one tidy row per episode.

One episode is one seed: ``env.reset(seed=s)`` and ``policy.reset(s)``, so every policy of a
comparison sees the same references, initial offsets and (for the same decisions) the same
fading. Episodes are independent; they run in the process pool (:mod:`training.pool`) when
``workers > 1`` and the rows come back in task order whatever the scheduling. Rows are written and
read as CSV one way (:func:`write_csv`, :func:`read_csv`).

**Reference rows** are names that play the best expert (:data:`~training.results.stats.SCORE_HIGH`)
in a changed setting (docs/benchmark.md, "Headroom rows"): ``limit:fast-drone`` lifts the drone's
speed bound to the largest value the configuration accepts (its drone grid capped at 1,000 points,
``python benchmarks/fast_drone_grid.py``), ``limit:perfect-links`` delivers every command,
``actuator:buffer`` gives the AGVs the buffered actuator (``control.actuator="buffer"``: a lost
command's AGV plays the rest of the last plan it received, MODEL.md §3; every other row holds); a
noise-floor row ``noise:NAME`` plays expert NAME with its drone grid at 1.4 m instead of 1.5 m (a
harmless change: a difference between two policies within its own is not one). They say how much
of the cost the drone's reach and the links decide under the expert's own planning, not a bound.
"""

from __future__ import annotations

import csv
import functools
import json
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple, cast

import gymnasium as gym
import numpy as np
from annotated_types import Le

import lawn_env
from agents import Policy, make_policy
from agents.anchors import anchor_name
from agents.base import JOINT
from agents.learned import zoo_agents
from agents.rollouts import Step, rollout
from agents.runs import read_run
from lawn_env import ScenarioConfig, central_env_id
from lawn_env.config import DroneConfig

from ..pool import pool_map
from .stats import SCORE_HIGH, SCORE_LOW

__all__ = ["TRANSIENT_SLOTS", "EpisodeSpec", "Play", "DEFAULT_PLAY", "episode_row", "build_policy", "run_episode",
           "split_cost",
           "evaluate", "run_entries", "per_slot_profile", "policy_env", "own_anchor", "learned_entries", "write_rows",
           "write_csv", "read_csv", "parse_bool", "LIMITS", "LIMIT_SETTINGS", "NOISE", "REFERENCE_ROWS",
           "is_reference_row", "limit_config", "resolve"]

#: Where an episode's control cost splits (docs/benchmark.md, "The cost's structure"): slots
#: 0..TRANSIENT_SLOTS-1 are the transient (the AGVs' recovery from their initial offsets while the
#: drone flies in from the area's edge), the slots from TRANSIENT_SLOTS on the sustained part.
#: ``--transient-slots`` of ``lawn evaluate`` and ``lawn benchmark`` moves it.
TRANSIENT_SLOTS = 20
#: Rows without a per-slot trace keep the saved tables small (100 seeds x many agents).
_DROPPED = ("stage_costs",)


class EpisodeSpec(NamedTuple):
    """One episode to play: the policy (or reference row) by name, the env it is evaluated on, the
    scenario, the seed and the policy's settings (``policy_kwargs`` of :func:`agents.make_policy`). A
    plain tuple of the same fields in this order is taken where a spec is."""

    policy: str
    env: str
    config: ScenarioConfig
    seed: int
    settings: Mapping[str, Any] = {}


@dataclass(frozen=True)
class Play:
    """How a batch of episodes is played: ``workers`` processes, a progress bar or not, and the
    transient/sustained split of the control cost (:func:`split_cost`)."""

    workers: int = 1
    progress: bool = True
    transient_slots: int = TRANSIENT_SLOTS


#: The default way to play: one process, a progress bar, the default split.
DEFAULT_PLAY = Play()


def _max_speed() -> float:
    """The validated upper bound of ``drone.max_speed_mps`` (the config's maximum)."""
    field = cast(Any, DroneConfig).__pydantic_fields__["max_speed_mps"]  # a pydantic dataclass
    return float(cast(float, next(m.le for m in field.metadata if isinstance(m, Le))))


#: name -> the lifted field (a dotted config key) and its value: the limits, and the buffered actuator
#: (``actuator:buffer``: every packet carries the plan, MODEL.md §3), the one row on another actuator.
LIMITS: dict[str, tuple[str, Any]] = {
    "limit:fast-drone": ("drone.max_speed_mps", _max_speed()),
    "limit:perfect-links": ("channel.perfect_links", True),
    "actuator:buffer": ("control.actuator", "buffer"),
}
#: name -> the settings of the expert a limit row plays with (bounded time per decision).
LIMIT_SETTINGS: dict[str, dict[str, Any]] = {
    "limit:fast-drone": {"max_drone_points": 1_000},
}
#: name -> the expert a noise-floor row plays and its settings that differ (harmlessly) from its defaults.
NOISE: dict[str, tuple[str, dict[str, Any]]] = {
    f"noise:{SCORE_HIGH}": (SCORE_HIGH, {"drone_spacing_m": 1.4}),
    "noise:rg-mpc": ("rg-mpc", {"drone_spacing_m": 1.4}),
}
#: Every reference row the tables show, in their order: the best expert's noise floor and the limits.
REFERENCE_ROWS: tuple[str, ...] = (f"noise:{SCORE_HIGH}", *LIMITS)


def is_reference_row(name: str) -> bool:
    """True for a limit or noise-floor row's name."""
    return name in LIMITS or name in NOISE


def limit_config(name: str, config: ScenarioConfig) -> ScenarioConfig:
    """The task ``config`` with the field of limit row ``name`` lifted (nothing else changes)."""
    if name not in LIMITS:
        raise ValueError(f"unknown limit row {name!r}; valid: {', '.join(LIMITS)}")
    key, value = LIMITS[name]
    return config.override({key: value})


def resolve(name: str, config: ScenarioConfig, policy_kwargs: Mapping[str, Any] | None = None
            ) -> tuple[str, ScenarioConfig, dict[str, Any]]:
    """(policy to build, config to play, policy settings) of a row name: a limit row becomes the
    best expert on its config with its settings, a noise-floor row its expert with its settings; any
    other name is returned as given."""
    kwargs = dict(policy_kwargs or {})
    if name in LIMITS:
        return SCORE_HIGH, limit_config(name, config), {**LIMIT_SETTINGS.get(name, {}), **kwargs}
    if name in NOISE:
        expert, settings = NOISE[name]
        return expert, config, {**settings, **kwargs}
    return name, config, kwargs


def episode_row(policy: Policy, env_id: str, config: ScenarioConfig, seed: int,
                transient_slots: int = TRANSIENT_SLOTS) -> dict[str, Any]:
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
    (:func:`resolve`) is an expert on its lifted config or with its settings; any other
    name is :func:`agents.make_policy` on ``config``."""
    name, played, kwargs = resolve(policy, config, policy_kwargs)
    return make_policy(name, played, env_id=env_id, **kwargs), played


def run_episode(policy: str, env_id: str, config: ScenarioConfig, seed: int,
                policy_kwargs: Mapping[str, Any] | None = None,
                transient_slots: int = TRANSIENT_SLOTS) -> dict[str, Any]:
    """One seeded episode of the named policy or reference row (:func:`build_policy`,
    :func:`episode_row`)."""
    agent, played = build_policy(policy, config, env_id, policy_kwargs)
    row = episode_row(agent, env_id, played, seed, transient_slots)
    row["policy"] = policy
    return row


def _run_task(task: EpisodeSpec | tuple[Any, ...], transient_slots: int = TRANSIENT_SLOTS) -> dict[str, Any]:
    spec = EpisodeSpec(*task)
    return run_episode(spec.policy, spec.env, spec.config, spec.seed, spec.settings, transient_slots)


def split_cost(stage_costs: Sequence[float], transient_slots: int = TRANSIENT_SLOTS) -> tuple[float, float]:
    """(transient, sustained) control cost of an episode's per-slot stage costs: the sums over slots
    ``0..transient_slots-1`` and ``transient_slots..``; they add up to the episode's control cost (an
    episode no longer than the split is all transient)."""
    if isinstance(transient_slots, bool) or not isinstance(transient_slots, (int, np.integer)) or transient_slots < 0:
        raise ValueError(f"transient_slots={transient_slots!r}: must be an integer >= 0")
    costs = np.asarray(stage_costs, dtype=float)
    return float(costs[:transient_slots].sum()), float(costs[transient_slots:].sum())


def evaluate(tasks: Iterable[EpisodeSpec | tuple[Any, ...]], workers: int = 1, progress: bool = True,
             desc: str = "episodes", transient_slots: int = TRANSIENT_SLOTS) -> list[dict[str, Any]]:
    """Play :class:`EpisodeSpec` tasks (or tuples of their fields); rows in task order, each with its
    ``transient_cost`` and ``sustained_cost`` split at ``transient_slots`` (:func:`split_cost`)."""
    split_cost((), transient_slots)  # a bad split fails before any episode
    return pool_map(functools.partial(_run_task, transient_slots=transient_slots), list(tasks), workers, progress, desc)


def policy_env(policy: str) -> str:
    """The env a policy is benchmarked on: a learned agent's own (multi-agent agents drive
    ``lawn/Joint-v1``), ``lawn/Joint-v1`` for everything else."""
    prefix, _, rest = policy.partition(":")
    if prefix == "zoo":
        agents = zoo_agents()
        if rest not in agents:
            raise ValueError(f"unknown zoo agent {rest!r}; shipped: {', '.join(agents)}")
        env: str = agents[rest]["evaluated_on"]
        return env
    if prefix in ("sb3", "bc", "marl"):
        env = read_run(rest).env
        return central_env_id(env)
    return JOINT


def own_anchor(policy: str) -> str | None:
    """The ``anchor:NAME`` whose zero action a learned agent acts around (from its recorded training
    interface); None for experts, baselines and anchors."""
    prefix, _, rest = policy.partition(":")
    if prefix == "zoo":
        return anchor_name(zoo_agents()[rest].get("interface"))
    if prefix in ("sb3", "bc", "marl"):
        return anchor_name(read_run(rest).interface)
    return None


def learned_entries(agents: Sequence[str], envs: Sequence[str] | None = None) -> list[tuple[str, str]]:
    """(policy, env) pairs of the learned protocol: per env, the two references, the anchors the
    env's agents act around, then the agents."""
    by_env: dict[str, list[str]] = {env: [] for env in (envs or ())}
    for agent in dict.fromkeys(agents):  # a repeated agent is one row
        by_env.setdefault(policy_env(agent), []).append(agent)
    out: list[tuple[str, str]] = []
    for env, members in by_env.items():
        anchors = sorted({a for a in map(own_anchor, members) if a is not None})
        out += [(p, env) for p in (SCORE_HIGH, SCORE_LOW, *anchors, *members)]
    return out


def run_entries(entries: Sequence[tuple[str, str]], config: ScenarioConfig, seeds: Sequence[int],
                play: Play = DEFAULT_PLAY, task: str = "default", desc: str = "benchmark",
                profiles: list[dict[str, Any]] | None = None) -> list[dict[str, Any]]:
    """Full episodes of every (policy, env) entry on every seed; rows with a ``task`` column and
    without the per-slot trace (its mean per slot appended to ``profiles`` when given,
    :func:`per_slot_profile`)."""
    tasks = [EpisodeSpec(policy, env, config, int(s)) for policy, env in entries for s in seeds]
    rows = evaluate(tasks, play.workers, play.progress, desc, play.transient_slots)
    for row in rows:
        row["task"] = task
    if profiles is not None:
        profiles += per_slot_profile(rows)
    for row in rows:
        for key in _DROPPED:
            row.pop(key, None)
    return rows


def per_slot_profile(rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """The mean stage cost per slot over the episodes of every (task, env, policy) of rows that
    hold their per-slot trace (``stage_costs``): one row per slot."""
    groups: dict[tuple[str, str, str], list[list[float]]] = {}
    for r in rows:
        key = (str(r.get("task", "default")), str(r["env"]), str(r["policy"]))
        groups.setdefault(key, []).append(json.loads(r["stage_costs"]))
    out = []
    for (task, env, policy), traces in groups.items():
        mean = np.mean(np.asarray(traces, dtype=float), axis=0)
        out += [{"task": task, "env": env, "policy": policy, "slot": n, "mean_stage_cost": float(c),
                 "episodes": len(traces)} for n, c in enumerate(mean)]
    return out


def write_rows(rows: list[dict[str, Any]], path: str | Path) -> Path:
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


def write_csv(rows: list[dict[str, Any]], path: Path | str, atomic: bool = False) -> Path:
    """Rows as CSV with the union of their keys as columns (first-seen order). ``atomic`` writes a
    temporary file, syncs it and renames it over ``path``, so a reader never sees half a table."""
    path = Path(path)
    fields: list[str] = []
    for row in rows:
        fields += [k for k in row if k not in fields]
    target = path.with_suffix(path.suffix + ".tmp") if atomic else path
    with target.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=fields)
        writer.writeheader()
        writer.writerows(rows)
        if atomic:
            fh.flush()
            os.fsync(fh.fileno())
    if atomic:
        os.replace(target, path)
    return path


def read_csv(path: Path | str) -> list[dict[str, str]]:
    """The rows of a CSV file as dicts of strings (an empty list when the file does not exist)."""
    path = Path(path)
    if not path.exists():
        return []
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


def parse_bool(value: object) -> bool:
    """A boolean table cell: a bool, or ``true``/``false``/``1``/``0`` in any case."""
    if isinstance(value, bool):
        return value
    text = str(value).strip().lower()
    if text in ("true", "1"):
        return True
    if text in ("false", "0"):
        return False
    raise ValueError(f"not a boolean table value: {value!r}")
