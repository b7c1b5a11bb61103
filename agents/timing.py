"""How much of a run's time an expert's decisions take: a :class:`DecisionClock` sums the wall time
of the decisions of every policy it times (:meth:`DecisionClock.timed`).

Training pays for an expert wherever one decides: the residual scheme's anchor and the paired
reward's shadow episode every step (:mod:`agents.residual`, :mod:`training.paired`), the labels of
behaviour cloning and DAgger, and the anchor of a residual agent under validation. A run times
them on one clock and records the sum beside its wall time (``run.json``: ``expert_decision_s``;
``summary.md``: ``expert_share``), so a run's cost splits into the learner's and the expert's.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from .base import Policy

__all__ = ["DecisionClock", "TimedPolicy"]


class DecisionClock:
    """The summed wall time (``seconds``) of the timed policies' ``act``."""

    def __init__(self) -> None:
        self.seconds = 0.0

    def timed(self, policy: Policy) -> TimedPolicy:
        """``policy`` acting on this clock (a policy already timed on it is returned as it is)."""
        if isinstance(policy, TimedPolicy) and policy.clock is self:
            return policy
        return TimedPolicy(policy, self)


class TimedPolicy(Policy):
    """``policy`` whose every ``act`` adds its wall time to ``clock``; otherwise the same policy (its
    name, scenario, env, state and plans)."""

    def __init__(self, policy: Policy, clock: DecisionClock):
        if not isinstance(policy, Policy):
            raise TypeError(f"policy={policy!r}: a built policy (agents.make_policy)")
        # no Policy.__init__: the timed policy's own scenario, layout and actions are this one's
        self.policy, self.clock = policy, clock
        self.name, self.env_ids, self.env_id = policy.name, policy.env_ids, policy.env_id
        self.config, self.layout, self.actions = policy.config, policy.layout, policy.actions

    @property
    def stateful(self) -> bool:  # type: ignore[override]
        return self.policy.stateful

    @property
    def last_plan(self) -> Any:  # type: ignore[override]
        return self.policy.last_plan

    def reset(self, seed: int | None = None) -> None:
        self.policy.reset(seed)

    def observation_hint(self, shape: tuple[int, ...]) -> str:
        return self.policy.observation_hint(shape)

    def act(self, obs: np.ndarray) -> np.ndarray:
        start = time.perf_counter()
        try:
            return self.policy.act(obs)
        finally:
            self.clock.seconds += time.perf_counter() - start
