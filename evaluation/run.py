"""Playing policies on seeded episodes: (policy, env, config, seed) to one tidy row per episode.

One episode is one seed: ``env.reset(seed=s)`` and ``policy.reset(s)``, so every policy of a
comparison sees the same references, initial offsets and (for the same decisions) the same
fading. Episodes are independent; they run in the process pool (:mod:`evaluation.pool`) when
``workers > 1`` and the rows come back in task order whatever the scheduling. Rows are written and
read as CSV one way (:func:`write_csv`, :func:`read_csv`).

**Reference rows** are names that play the best expert (:data:`~evaluation.stats.SCORE_HIGH`)
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

import functools
import math
import time
from collections.abc import Iterable, Mapping, Sequence
from typing import Any, NamedTuple, cast

import gymnasium as gym
import numpy as np
from annotated_types import Le

import lawn_env
from agents import POLICIES, Policy, make_policy
from agents.anchors import anchor_name
from agents.base import JOINT
from agents.learned import zoo_record
from agents.runs import read_run
from lawn_env import ScenarioConfig, central_env_id
from lawn_env.config import DroneConfig
from lawn_env.metrics import EpisodeMetrics
from lawn_env.rollouts import Step, rollout

from .episode import TRANSIENT_SLOTS, Entry, EpisodeResult, EpisodeSpec, Results
from .pool import pool_map
from .stats import SCORE_HIGH, SCORE_LOW

#: The most seeds a worker plays together (:func:`play_together`).
LOCKSTEP = 32

__all__ = ["Resolved", "Built", "CostSplit", "episode_row", "build_policy", "run_episode", "split_cost",
           "play_together", "Tally", "LOCKSTEP",
           "evaluate", "per_slot_profile", "policy_env", "own_anchor", "learned_entries", "LIMITS",
           "LIMIT_SETTINGS", "NOISE", "REFERENCE_ROWS", "is_reference_row", "limit_config", "resolve"]


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
LIMIT_SETTINGS: dict[str, Mapping[str, Any]] = {
    "limit:fast-drone": {"max_drone_points": 1_000},
}
#: name -> the expert a noise-floor row plays and its settings that differ (harmlessly) from its defaults.
NOISE: dict[str, tuple[str, Mapping[str, Any]]] = {
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


class Resolved(NamedTuple):
    """What a row name plays: the policy to build, the config it plays on and its settings."""

    policy: str
    config: ScenarioConfig
    settings: Mapping[str, Any]


class Built(NamedTuple):
    """A row's policy, built, and the config it plays on."""

    policy: Policy
    config: ScenarioConfig


class CostSplit(NamedTuple):
    """An episode's control cost over its first slots (``transient``) and the rest (``sustained``)."""

    transient: float
    sustained: float


def resolve(name: str, config: ScenarioConfig, policy_kwargs: Mapping[str, Any] | None = None) -> Resolved:
    """What a row name plays (the policy to build, the config, its settings): a limit row becomes the
    best expert on its config with its settings, a noise-floor row its expert with its settings; any
    other name is returned as given."""
    kwargs = dict(policy_kwargs or {})
    if name in LIMITS:
        return Resolved(SCORE_HIGH, limit_config(name, config), {**LIMIT_SETTINGS.get(name, {}), **kwargs})
    if name in NOISE:
        expert, settings = NOISE[name]
        return Resolved(expert, config, {**settings, **kwargs})
    return Resolved(name, config, kwargs)


def episode_row(policy: Policy, env_id: str, config: ScenarioConfig, seed: int,
                transient_slots: int = TRANSIENT_SLOTS) -> EpisodeResult:
    """One seeded, full episode of the unmodified scenario (``env_id`` of ``lawn_env.ENV_IDS``)
    under a built policy (:func:`agents.rollout`): MODEL.md §6's metrics, the decision statistics and
    the control cost's transient and sustained parts (:func:`split_cost`)."""
    if env_id not in lawn_env.ENV_IDS:
        raise ValueError(f"unknown env id {env_id!r}; valid: {', '.join(lawn_env.ENV_IDS)}")
    tally = Tally()

    def on_step(step: Step) -> None:
        tally.add(policy.last_plan, step.info, step.decision_s)

    env = gym.make(env_id, config=config)
    episode = rollout(env, policy, seed, on_step=on_step)
    env.close()
    return tally.result(policy.name, env_id, seed, episode.record, transient_slots)


class Tally:
    """What an episode's steps add up to beside the env's metrics: the decision times, the AO iterations
    of the plans behind the actions, the QP fallbacks (the plans' and the env's MPC's) and the stage costs."""

    def __init__(self) -> None:
        self.decision_s: list[float] = []
        self.iterations: list[int] = []
        self.stage_costs: list[float] = []
        self.fallbacks = 0

    def add(self, plan: Any, info: Mapping[str, Any], decision_s: float) -> None:
        """One step: the plan behind its action (None: no plan), the env's info, the decision's time."""
        if plan is not None:
            self.iterations.append(plan.iterations)
            self.fallbacks += plan.info.get("qp_fallbacks", 0)
        self.fallbacks += int(info.get("mpc_fallbacks", 0))
        self.stage_costs.append(float(info["stage_cost"]))
        self.decision_s.append(decision_s)

    def result(self, policy: str, env_id: str, seed: int, metrics: EpisodeMetrics,
               transient_slots: int) -> EpisodeResult:
        """The episode's record from the env's ``metrics`` (MODEL.md §6) and the steps added."""
        transient, sustained = split_cost(self.stage_costs, transient_slots)
        decision_s = np.array(self.decision_s)
        return EpisodeResult.from_metrics(
            metrics, policy=policy, env=env_id, seed=seed,
            decision_time_median_s=float(np.median(decision_s)) if decision_s.size else math.nan,
            decision_time_p95_s=float(np.percentile(decision_s, 95)),
            ao_iterations_mean=float(np.mean(self.iterations)) if self.iterations else math.nan,
            qp_fallbacks=self.fallbacks, transient_cost=transient, sustained_cost=sustained,
            transient_slots=int(transient_slots), stage_costs=self.stage_costs)


def build_policy(policy: str, config: ScenarioConfig, env_id: str | None = None,
                 policy_kwargs: Mapping[str, Any] | None = None) -> Built:
    """The policy a row name plays and the config it plays on: a limit or noise-floor row
    (:func:`resolve`) is an expert on its lifted config or with its settings; any other
    name is :func:`agents.make_policy` on ``config``."""
    name, played, kwargs = resolve(policy, config, policy_kwargs)
    return Built(make_policy(name, played, env_id=env_id, **kwargs), played)


def run_episode(policy: str, env_id: str, config: ScenarioConfig, seed: int,
                policy_kwargs: Mapping[str, Any] | None = None,
                transient_slots: int = TRANSIENT_SLOTS) -> EpisodeResult:
    """One seeded episode of the named policy or reference row (:func:`build_policy`,
    :func:`episode_row`), under that name."""
    agent, played = build_policy(policy, config, env_id, policy_kwargs)
    return episode_row(agent, env_id, played, seed, transient_slots).with_(policy=policy)


def _run_chunk(specs: Sequence[EpisodeSpec], transient_slots: int = TRANSIENT_SLOTS) -> list[EpisodeResult]:
    """Episodes of one policy, env, scenario and settings (:func:`_chunks`): played together in lockstep
    when the policy decides a batch at once (:func:`play_together`: each record is the one its seed gets
    alone), else one by one (:func:`run_episode`)."""
    first = specs[0]
    if len(specs) > 1:
        agent, played = build_policy(first.policy, first.config, first.env, first.settings)
        if agent.batched:
            rows = play_together(agent, first.env, played, [s.seed for s in specs], transient_slots)
            return [row.with_(policy=first.policy) for row in rows]
    return [run_episode(s.policy, s.env, s.config, s.seed, s.settings, transient_slots) for s in specs]


def _chunks(specs: list[EpisodeSpec], workers: int) -> list[list[EpisodeSpec]]:
    """The tasks in order, consecutive tasks of one policy, env, scenario and settings together when the
    policy decides a batch at once (:func:`batches`; at most :data:`LOCKSTEP`, split evenly over the
    workers); every other task alone."""
    out: list[list[EpisodeSpec]] = []
    start = 0
    while start < len(specs):
        key = (*specs[start][:3], dict(specs[start].settings))
        end = start + 1
        while end < len(specs) and (*specs[end][:3], dict(specs[end].settings)) == key:
            end += 1
        group = specs[start:end]
        if len(group) > 1 and batches(group[0]):
            size = min(LOCKSTEP, math.ceil(len(group) / max(1, workers)))
            out += [group[i:i + size] for i in range(0, len(group), size)]
        else:
            out += [[spec] for spec in group]
        start = end
    return out


@functools.lru_cache(maxsize=64)
def _batches(policy: str, env: str, config: ScenarioConfig, settings: tuple[tuple[str, Any], ...]) -> bool:
    name, _, _ = resolve(policy, config)
    if name not in POLICIES or gym.spec(env).vector_entry_point is None:  # learned agents, anchors, v0 ids
        return False
    agent, _ = build_policy(policy, config, env, dict(settings))
    return bool(agent.batched)


def batches(spec: EpisodeSpec) -> bool:
    """True when the spec's policy decides a batch of scenarios at once (``dv-mpc``'s planner) on an env
    with a native vector env (not the v0 ids): its seeds are played in lockstep (:func:`play_together`)."""
    try:
        return _batches(spec.policy, spec.env, spec.config, tuple(sorted(dict(spec.settings).items())))
    except TypeError:  # settings that cannot key a cache (unhashable values): one by one
        return False


def evaluate(tasks: Iterable[EpisodeSpec], workers: int = 1, progress: bool = True,
             desc: str = "episodes", transient_slots: int = TRANSIENT_SLOTS) -> list[EpisodeResult]:
    """Play :class:`.episode.EpisodeSpec` tasks; results in task order,
    each with its ``transient_cost`` and ``sustained_cost`` split at ``transient_slots``
    (:func:`split_cost`)."""
    split_cost((), transient_slots)  # a bad split fails before any episode
    specs = list(tasks)
    wrong = next((i for i, s in enumerate(specs) if not isinstance(s, EpisodeSpec)), None)
    if wrong is not None:  # a plain tuple's fields would be read by position, in silence
        raise TypeError(f"evaluate: task {wrong} is {type(specs[wrong]).__name__} {specs[wrong]!r}; expected an "
                        "EpisodeSpec(policy, env, config, seed, settings)")
    chunks = _chunks(specs, workers)
    played = pool_map(functools.partial(_run_chunk, transient_slots=transient_slots), chunks, workers, progress, desc,
                      weight=len)
    return [row for chunk in played for row in chunk]


def split_cost(stage_costs: Sequence[float], transient_slots: int = TRANSIENT_SLOTS) -> CostSplit:
    """(transient, sustained) control cost of an episode's per-slot stage costs: the sums over slots
    ``0..transient_slots-1`` and ``transient_slots..``; they add up to the episode's control cost (an
    episode no longer than the split is all transient)."""
    if isinstance(transient_slots, bool) or not isinstance(transient_slots, (int, np.integer)) or transient_slots < 0:
        raise ValueError(f"transient_slots={transient_slots!r}: must be an integer >= 0")
    costs = np.asarray(stage_costs, dtype=float)
    return CostSplit(float(costs[:transient_slots].sum()), float(costs[transient_slots:].sum()))


def play_together(policy: Policy, env_id: str, config: ScenarioConfig, seeds: Sequence[int],
                  transient_slots: int = TRANSIENT_SLOTS) -> list[EpisodeResult]:
    """The full episodes of ``seeds`` under ``policy`` (built for ``config``), in lockstep: one record per
    seed, in order, each the one :func:`episode_row` gives its seed alone.

    A policy that decides a batch at once (``Policy.batched``: ``dv-mpc``'s planner) plays them through
    the native vector env with independent draws (``reset(options={"independent_draws": True})``):
    scenario i's slots draw from its own seed's generator and the policy keeps each scenario's state
    apart (``tests/test_lockstep.py``), but a slot costs one Python-level decision for all of them. A
    decision's time is its share of the batch's (the batch's time over its size)."""
    if env_id not in lawn_env.ENV_IDS:
        raise ValueError(f"unknown env id {env_id!r}; valid: {', '.join(lawn_env.ENV_IDS)}")
    count = len(seeds)
    env = gym.make_vec(env_id, num_envs=count, vectorization_mode="vector_entry_point", config=config)
    obs, _ = env.reset(seed=[int(s) for s in seeds],  # type: ignore[arg-type]  # the native env takes a list
                       options={"independent_draws": True})
    policy.reset_scenarios(seeds)
    tallies = [Tally() for _ in seeds]
    metrics: list[EpisodeMetrics | None] = [None] * count
    playing = np.ones(count, dtype=bool)
    while playing.any():
        start = time.perf_counter()
        actions = policy.act_scenarios(obs)
        share = (time.perf_counter() - start) / count
        plans = policy.last_plans or [None] * count
        obs, _, terminated, truncated, info = env.step(actions)
        for i in np.flatnonzero(playing).tolist():
            tallies[i].add(plans[i], {key: value[i] for key, value in info.items() if not key.startswith("_")}, share)
            if terminated[i] or truncated[i]:
                metrics[i] = EpisodeMetrics.from_dict(info["episode_metrics"][i])
                playing[i] = False
    env.close()
    return [tally.result(policy.name, env_id, int(seed), _ended(found), transient_slots)
            for tally, seed, found in zip(tallies, seeds, metrics, strict=True)]


def _ended(metrics: EpisodeMetrics | None) -> EpisodeMetrics:
    assert metrics is not None  # the loop ran until every episode ended
    return metrics



def policy_env(policy: str) -> str:
    """The env a policy is benchmarked on: a learned agent's own (multi-agent agents drive
    ``lawn/Joint-v1``; ``zero:AGENT`` the agent's), ``lawn/Joint-v1`` for everything else."""
    prefix, _, rest = policy.partition(":")
    if prefix == "zero":
        return policy_env(rest)
    if prefix == "zoo":
        evaluated = zoo_record(rest).evaluated_on
        if evaluated is None:
            raise ValueError(f"zoo:{rest}: its agent.json names no env it is evaluated_on (lawn zoo build writes it)")
        return evaluated
    if prefix in ("sb3", "bc", "marl"):
        env = read_run(rest).env
        return central_env_id(env)
    return JOINT


def own_anchor(policy: str) -> str | None:
    """What a learned agent acts around: ``zero:AGENT`` for a residual agent (its anchor policy
    through its scheme), else the ``anchor:NAME`` of its recorded training interface; None for
    experts, baselines and anchors."""
    prefix, _, rest = policy.partition(":")
    if prefix == "zoo":
        record = zoo_record(rest)
    elif prefix in ("sb3", "bc", "marl"):
        record = read_run(rest).record
    else:
        return None
    return f"zero:{policy}" if record.residual else anchor_name(record.interface)


def learned_entries(agents: Sequence[str], envs: Sequence[str] | None = None) -> list[Entry]:
    """The learned protocol's entries: per env, the two references, the anchors the env's agents act
    around, then the agents (each with its anchor, :func:`own_anchor`)."""
    by_env: dict[str, list[str]] = {env: [] for env in (envs or ())}
    for agent in dict.fromkeys(agents):  # a repeated agent is one row
        by_env.setdefault(policy_env(agent), []).append(agent)
    out: list[Entry] = []
    for env, members in by_env.items():
        anchors = {a: own_anchor(a) for a in members}
        out += [Entry(p, env) for p in (SCORE_HIGH, SCORE_LOW, *sorted({a for a in anchors.values() if a}))]
        out += [Entry(a, env, anchors[a]) for a in members]
    return out


def per_slot_profile(results: Results) -> list[dict[str, str | int | float]]:
    """The mean stage cost per slot over the episodes of every (task, env, policy) of results that
    hold their per-slot trace (``stage_costs``): one row per slot (``per_slot.csv``)."""
    groups: dict[tuple[str, str, str], list[np.ndarray]] = {}
    for r in results:
        if r.stage_costs is not None:
            groups.setdefault((r.task or "default", r.env, r.policy), []).append(r.stage_costs)
    out: list[dict[str, str | int | float]] = []
    for (task, env, policy), traces in groups.items():
        mean = np.mean(np.asarray(traces, dtype=float), axis=0)
        out += [{"task": task, "env": env, "policy": policy, "slot": n, "mean_stage_cost": float(c),
                 "episodes": len(traces)} for n, c in enumerate(mean)]
    return out
