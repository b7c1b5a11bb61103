"""The base of every policy and the planner protocol: what a policy is built from and what it
offers, and what plans a slot from the full state (see :mod:`agents.policies` for the registry
of named policies)."""

from __future__ import annotations

import copy
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np

from lawn_env import ObservationLayout, env_role
from lawn_env.core import Snapshot
from lawn_env.presets import ConfigLike, resolve_config
from lawn_env.spaces import DirectActions

if TYPE_CHECKING:
    from .problem import Plan

__all__ = ["Policy", "Planner", "BatchPlanner", "JOINT", "COMM"]

JOINT, COMM = "lawn/Joint-v1", "lawn/Comm-v1"


class Planner(Protocol):
    """Plans one slot from the full state: the experts' solvers (:class:`agents.AOSolver`,
    :class:`agents.ReducedGradientPlanner`, :class:`agents.GlobalPlanner`) and the planner
    policies. ``reset`` drops what the planner carries across slots (warm starts)."""

    def reset(self) -> None: ...

    def plan(self, snapshot: Snapshot) -> Plan: ...


@runtime_checkable
class BatchPlanner(Planner, Protocol):
    """A :class:`Planner` that may plan B scenarios in one call (:class:`agents.DeliveryValuePlanner`):
    ``batches`` says whether it does (with the settings it has), ``plan_scenarios`` plans them, scenario
    i's plan the one it gets planned alone."""

    @property
    def batches(self) -> bool: ...

    def plan_scenarios(self, snapshots: Sequence[Snapshot]) -> list[Plan]: ...


class Policy:
    """Base of every policy: config, target environment, seeding and SB3-style ``predict``."""

    name = "policy"
    env_ids: tuple[str, ...] = (JOINT, COMM)
    #: True when the policy keeps per-episode state (it then drives one environment at a time)
    stateful = False
    #: The plan behind the last action (planner policies; None for policies that do not plan)
    last_plan: Plan | None = None
    #: The plans behind the last :meth:`act_scenarios`'s actions, one per scenario (None entries: no plan)
    last_plans: list[Plan | None] | None = None
    #: True when :meth:`act_scenarios` decides the batch in one call (the others play it scenario by scenario)
    batched = False
    _rows: list[Policy] | None = None  # the scenarios' copies (a policy playing them one by one)
    _batch = 0  # the scenarios reset_scenarios started

    def __init__(self, config: ConfigLike = None, env_id: str = JOINT,
                 seed: int | None = None):
        self.config = resolve_config(config)
        if env_id not in self.env_ids:
            raise ValueError(f"policy {self.name!r} drives {', '.join(self.env_ids)}; got env_id={env_id!r}")
        self.env_id = env_id
        self.layout = ObservationLayout(self.config)
        #: The v0 actions of ``env_id`` (what every policy's action is, whatever it plans with)
        self.actions = DirectActions(self.config, env_role(env_id))
        self._seed_rng = np.random.default_rng(seed)

    def reset(self, seed: int | None = None) -> None:
        """Start an episode; ``seed`` fixes any randomness of the policy (else its own stream)."""
        rng = np.random.default_rng(seed) if seed is not None else self._seed_rng
        self._on_reset(rng)

    def _on_reset(self, rng: np.random.Generator) -> None:
        pass

    def act(self, obs: np.ndarray) -> np.ndarray:  # pragma: no cover - interface
        raise NotImplementedError

    # ------------------------------------------------------------------ B scenarios at once
    def reset_scenarios(self, seeds: Sequence[int | None]) -> None:
        """Start B episodes for :meth:`act_scenarios`, scenario i's as ``reset(seeds[i])`` starts one. Here
        (a policy without a batched decision, a user's own among them) each scenario gets a copy of this
        policy that plays it alone (a seed of None draws the copy's own seed from this policy's stream, so
        no two copies share their randomness); a policy with no per-episode state and nothing drawn at
        reset (``stateful`` False, no ``_on_reset`` of its own) serves every scenario itself, and so does a
        policy that decides a batch at once (:attr:`batched`: it keeps the scenarios apart itself)."""
        seeds = list(seeds)
        if not seeds:
            raise ValueError("seeds is empty: reset_scenarios starts one episode per seed")
        self._rows, self._batch = None, len(seeds)
        if self.batched:
            self.reset(seeds[0])
            return
        if not self.stateful and type(self)._on_reset is Policy._on_reset:
            self.reset(seeds[0])
            self._rows = [self] * len(seeds)
            return
        template = copy.deepcopy(self)
        self._rows = [copy.deepcopy(template) for _ in seeds]
        for row, seed in zip(self._rows, seeds, strict=True):
            row.reset(int(self._seed_rng.integers(2**63)) if seed is None else seed)

    def act_scenarios(self, observations: np.ndarray) -> np.ndarray:
        """The actions (B, ...) of the observations (B, obs) of the B scenarios :meth:`reset_scenarios` started,
        each continuing its own episode: scenario i's action is the one it gets played alone. Here one
        scenario at a time (:meth:`act` of its copy); :attr:`last_plans` holds the plans behind them."""
        obs = self.check_scenarios(observations)
        rows = self._rows
        assert rows is not None
        actions = np.stack([row.act(o) for row, o in zip(rows, obs, strict=True)])
        self.last_plans = [row.last_plan for row in rows]
        return actions

    def check_scenarios(self, observations: Any) -> np.ndarray:
        """``observations`` as float32 (B, obs) after checking they are one per scenario of the batch
        :meth:`reset_scenarios` started, each an observation of this policy's scenario, none of them NaN."""
        size = self._batch
        if not size:
            raise ValueError("act_scenarios before reset_scenarios: start the scenarios' episodes with "
                             "reset_scenarios(seeds)")
        obs = np.asarray(observations)
        if obs.ndim != 2 or obs.shape[0] != size:
            raise ValueError(f"observations has shape {obs.shape}; this batch has {size} scenarios: expected "
                             f"({size}, {self.layout.size})")
        checked = np.stack([self.check_observation(o) for o in obs])
        if np.isnan(checked).any():
            raise ValueError(f"observations of scenarios {np.flatnonzero(np.isnan(checked).any(axis=1)).tolist()} "
                             "hold NaN")
        return checked

    def check_observation(self, obs: Any) -> np.ndarray:
        """``obs`` as float32 after checking it is one observation of this policy's scenario: every
        policy rejects another shape with the same message (:meth:`lawn_env.ObservationLayout.check`),
        followed by :meth:`observation_hint`."""
        array = np.asarray(obs)
        hint = self.observation_hint(array.shape) if array.shape != (self.layout.size,) else ""
        return np.asarray(self.layout.check(array, hint), dtype=np.float32)

    def observation_hint(self, shape: tuple[int, ...]) -> str:
        """What to do about an observation of ``shape``, not this policy's (learned policies: the
        fleet size they were built for and how to pass the env's config); empty by default."""
        return ""

    def predict(self, observation: np.ndarray, state: Any = None, episode_start: np.ndarray | None = None,
                deterministic: bool = True) -> tuple[np.ndarray, Any]:
        """Stable-Baselines3's signature: a single observation or a batch of them."""
        obs = np.asarray(observation, dtype=np.float32)
        if obs.ndim == 1:
            return self.act(obs), state
        if obs.ndim != 2:
            raise ValueError(f"observation has shape {obs.shape}; expected ({self.layout.size},) or "
                             f"(n_envs, {self.layout.size})")
        if obs.shape[0] > 1 and self.stateful:
            raise ValueError(f"policy {self.name!r} keeps per-episode state: evaluate it on one environment at a time")
        if episode_start is not None and np.asarray(episode_start).any():
            self.reset()
        return np.stack([self.act(o) for o in obs]), state
