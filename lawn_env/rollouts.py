"""The one episode loop: every part of the package that runs episodes calls :func:`rollout`.

In the spirit of Stable-Baselines3's ``evaluate_policy``, with the hooks the package's users
need: ``on_step`` sees every slot (observation, action, decision time, the env's info and,
with ``snapshots=True``, the full state the action was chosen in) and may end the episode early;
``max_steps`` caps its length. Evaluation, the demo, behaviour cloning, the optimality-gap and
convergence studies, the figures and the benchmarks all run their episodes through it, so a
decision time or a seed means the same thing in each of them.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol, cast

import gymnasium as gym
import numpy as np

from .core import Snapshot
from .metrics import EpisodeMetrics

__all__ = ["Actor", "Step", "Episode", "rollout"]


class Actor(Protocol):
    """What :func:`rollout` drives: every :class:`agents.Policy` is one."""

    def reset(self, seed: int | None = None) -> None: ...

    def act(self, obs: np.ndarray) -> np.ndarray: ...


class _Snapshots(Protocol):
    """A lawn environment (unwrapped): its state as a planner's :class:`Snapshot`."""

    def snapshot(self) -> Snapshot: ...


@dataclass(frozen=True)
class Step:
    """One slot of a rollout, as ``on_step`` sees it."""

    slot: int  # n: the slot the action was chosen in
    obs: np.ndarray  # the observation the action was chosen from
    action: np.ndarray
    decision_s: float  # wall time of policy.act
    reward: float
    info: dict[str, Any]  # the env's info of this step
    snapshot: Snapshot | None  # the state before the action (rollout(..., snapshots=True)), else None


@dataclass(frozen=True)
class Episode:
    """What a rollout produced: its length, how it ended, the last step's info and the decision
    times of every slot."""

    seed: int | None
    length: int
    terminated: bool
    truncated: bool
    info: dict[str, Any]  # the last step's info (with "episode_metrics" when the episode ended)
    decision_s: np.ndarray = field(repr=False)

    @property
    def ended(self) -> bool:
        """True when the env ended the episode (not ``on_step`` or ``max_steps``)."""
        return self.terminated or self.truncated

    @property
    def metrics(self) -> dict[str, Any]:
        """The env's episode metrics (MODEL.md §6); only an ended episode has them."""
        if "episode_metrics" not in self.info:
            raise ValueError(f"the episode of seed {self.seed} stopped after {self.length} steps before the env "
                             "ended it: it has no episode metrics")
        metrics: dict[str, Any] = self.info["episode_metrics"]
        return metrics

    @property
    def record(self) -> EpisodeMetrics:
        """:attr:`metrics` as the typed record (:class:`lawn_env.metrics.EpisodeMetrics`)."""
        return EpisodeMetrics.from_dict(self.metrics)

    @property
    def decision_time_median_s(self) -> float:
        return float(np.median(self.decision_s)) if self.decision_s.size else float("nan")


def rollout(env: gym.Env, policy: Actor, seed: int | None, *, on_step: Callable[[Step], bool | None] | None = None,
            snapshots: bool = False, max_steps: int | None = None) -> Episode:
    """Run one episode of ``env`` (a lawn environment, wrapped or not) under ``policy``:
    ``env.reset(seed=seed)``, ``policy.reset(seed)``, then ``policy.act`` and ``env.step`` until the
    env terminates or truncates, ``on_step`` returns True, or ``max_steps`` steps have run.

    ``snapshots=True`` hands ``on_step`` the full state each action was chosen in
    (``env.unwrapped.snapshot()``, taken before ``policy.act``)."""
    if max_steps is not None and (not isinstance(max_steps, (int, np.integer)) or max_steps < 1):
        raise ValueError(f"max_steps={max_steps!r}: must be a positive integer or None")
    obs, info = env.reset(seed=seed)
    policy.reset(seed)
    decision_s: list[float] = []
    terminated = truncated = False
    while True:
        snapshot = cast(_Snapshots, env.unwrapped).snapshot() if snapshots else None
        start = time.perf_counter()
        action = policy.act(obs)
        decision_s.append(time.perf_counter() - start)
        next_obs, reward, terminated, truncated, info = env.step(action)
        stop = False
        if on_step is not None:
            stop = bool(on_step(Step(len(decision_s) - 1, obs, action, decision_s[-1], float(reward), info, snapshot)))
        obs = next_obs
        if terminated or truncated or stop or (max_steps is not None and len(decision_s) >= max_steps):
            break
    return Episode(seed=seed, length=len(decision_s), terminated=bool(terminated), truncated=bool(truncated),
                   info=info, decision_s=np.array(decision_s))
