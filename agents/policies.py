"""The planner policies, the built-in entries of the policy registry, and building a policy by name.

Every policy is built from a scenario config (not from an environment), drives one environment
id, and offers ``reset(seed)``, ``act(obs) -> action`` and Stable-Baselines3's
``predict(observation, state, episode_start, deterministic) -> (action, state)``, so the command
line and SB3's ``evaluate_policy`` treat them all alike. Planners also offer ``plan(snapshot)``.

``make_policy(name, config)`` builds a registered policy (:data:`POLICIES`, :mod:`agents.registry`); the
built-in entries, each with its one-line description and the lists it is on, are
:data:`BUILT_IN_POLICIES`. The lists of policies (:data:`BENCHMARK_POLICIES`, :data:`PAPER_POLICIES`,
the suite's, the experiments' experts) are views of the registry.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from lawn_env import ObservationLayout, ScenarioConfig
from lawn_env.core import Decisions, Snapshot, later_increments
from lawn_env.drone import move_drone
from lawn_env.dynamics import command_mask, planning_period
from lawn_env.presets import ConfigLike, resolve_config

from .ao import AOSettings, AOSolver
from .base import COMM, JOINT, BatchPlanner, Planner, Policy
from .dv_mpc import DeliverySettings, DeliveryValuePlanner
from .global_mpc import GlobalPlanner, GlobalSettings
from .learned import LOADERS, learned_name_forms
from .problem import Plan
from .registry import POLICIES, Names, PolicyEntry, register
from .residual import PARTS, ResidualActions, check_residual
from .rg_mpc import ReducedGradientPlanner, ReducedSettings
from .scripted import HeuristicPolicy
from .timing import DecisionClock
from .tracking import PIDGains, lqr_gain, lqr_rollout, pid_rollout

__all__ = [
    "Policy",
    "PlannerPolicy",
    "AOPolicy",
    "AOMPCPolicy",
    "EPAPolicy",
    "SFPolicy",
    "PIDPolicy",
    "LQRPolicy",
    "RGMPCPolicy",
    "DVMPCPolicy",
    "GlobalMPCPolicy",
    "BUILT_IN_POLICIES",
    "BENCHMARK_POLICIES",
    "PAPER_POLICIES",
    "POLICIES",
    "make_policy",
    "attach_residual",
    "policy_names",
    "is_policy_name",
    "snapshot_from_observation",
]

def snapshot_from_observation(layout: ObservationLayout, config: ScenarioConfig, obs: np.ndarray) -> Snapshot:
    """The planner's state recovered from an observation (float32-exact, see ObservationLayout.decode)."""
    d = layout.decode(obs)
    return Snapshot(x_aug=d["x_aug"], reference=d["reference"], drone_position=d["drone_position"],
                    slot=d["slot"], config=config, last_power_w=d["last_power_w"], buffer=d["buffer"])


class PlannerPolicy(Policy):
    """A policy that plans from the full state (``plan(snapshot)``, its solver's plan unless it plans
    otherwise) and acts on observations. A subclass names its solver in :meth:`_make_solver`."""

    stateful = True
    solver: Planner

    def __init__(self, config: ConfigLike = None, env_id: str = JOINT, seed: int | None = None, **settings: Any):
        super().__init__(config, env_id, seed)
        self.solver = self._make_solver(**settings)

    def _make_solver(self, **settings: Any) -> Planner:  # pragma: no cover - interface
        raise NotImplementedError(f"{type(self).__name__} names no solver: define _make_solver (AOPolicy's is the "
                                  "paper's AO solver)")

    def _on_reset(self, rng: np.random.Generator) -> None:
        self.solver.reset()
        self.last_plan = None

    def plan(self, snapshot: Snapshot) -> Plan:
        return self.solver.plan(snapshot)

    def _commands(self, snapshot: Snapshot) -> np.ndarray:
        """The horizon slots where a command goes out (move blocking, MODEL.md §7)."""
        return command_mask(snapshot.slot, self.config.control.horizon, planning_period(self.config))

    def act(self, obs: np.ndarray) -> np.ndarray:
        snapshot = snapshot_from_observation(self.layout, self.config, obs)
        plan = self.plan(snapshot)
        self.last_plan = plan
        return self.action(plan, snapshot)

    @property
    def batched(self) -> bool:  # type: ignore[override]  # a property of the solver here
        """True when the solver plans a batch at once (``dv-mpc``'s, with the compiled QP backend; on
        ``lawn/Comm-v1`` under the paper's law it plans as ``rg-mpc``, one scenario at a time)."""
        return isinstance(self.solver, BatchPlanner) and self.solver.batches

    def act_scenarios(self, observations: np.ndarray) -> np.ndarray:
        """:meth:`Policy.act_scenarios`; a solver that plans batches plans the B scenarios in one call."""
        if not self.batched:
            return super().act_scenarios(observations)
        obs = self.check_scenarios(observations)
        assert isinstance(self.solver, BatchPlanner)  # what batched says
        snapshots = [snapshot_from_observation(self.layout, self.config, o) for o in obs]
        plans = self.solver.plan_scenarios(snapshots)
        self.last_plans = list(plans)
        return np.stack([self.action(plan, snapshot) for plan, snapshot in zip(plans, snapshots, strict=True)])

    def action(self, plan: Plan, snapshot: Snapshot) -> np.ndarray:
        """The normalized action of ``self.env_id`` that carries out ``plan`` (under the buffered
        actuator Joint's carries the rest of the planned sequence, :func:`lawn_env.core.later_increments`)."""
        increment = plan.increments[:, 0] if self.env_id == JOINT else None
        later = later_increments(plan.increments, self.actions.buffer_length) if self.actions.plan_size else None
        return self.actions.encode(Decisions(increment, plan.power_w, plan.drone_position, later), snapshot.x_aug,
                                   None, snapshot.drone_position)


class AOPolicy(PlannerPolicy):
    """A planner on the paper's AO solver (:class:`agents.AOSolver`): the paper's expert and the baselines
    that fix some of its blocks."""

    solver: AOSolver

    def _make_solver(self, **settings: Any) -> AOSolver:
        return AOSolver(self.config, AOSettings(**settings))


class AOMPCPolicy(AOPolicy):
    """The paper's expert: alternating optimization over control, power and drone (agents.ao)."""

    name = "ao-mpc"


class EPAPolicy(AOPolicy):
    """Equal power allocation P_max / K; MPC control and drone optimization as the expert."""

    name = "epa"

    def plan(self, snapshot: Snapshot) -> Plan:
        return self.solver.solve(snapshot, blocks=("control", "drone"), power_w=self.solver.equal_power())


class SFPolicy(AOPolicy):
    """Straight flight: a fixed heading (``heading_rad``, default east, across the area from the
    start) at a constant speed drawn uniformly from (0, V_max] at each episode's reset; the drone
    stops at the area's edge. MPC control and Algorithm 1 power as the expert."""

    name = "sf"

    def __init__(self, config: ConfigLike = None, env_id: str = JOINT, seed: int | None = None,
                 heading_rad: float = 0.0, **settings: Any):
        if not math.isfinite(heading_rad):
            raise ValueError(f"heading_rad={heading_rad!r} must be finite")
        super().__init__(config, env_id, seed, **settings)
        self.heading = np.array([math.cos(heading_rad), math.sin(heading_rad)])
        self.speed_mps = self.config.drone.max_speed_mps  # drawn at reset

    def _on_reset(self, rng: np.random.Generator) -> None:
        super()._on_reset(rng)
        self.speed_mps = self.config.drone.max_speed_mps * (1.0 - rng.random())  # in (0, V_max]

    def plan(self, snapshot: Snapshot) -> Plan:
        c = self.config
        q_next = move_drone(snapshot.drone_position, self.speed_mps * self.heading, c.drone.max_speed_mps, c.slot_s,
                            c.area_m)
        return self.solver.solve(snapshot, blocks=("control", "power"), drone_position=q_next)


class PIDPolicy(AOPolicy):
    """Predictive PID: the PID law rolled out over the horizon replaces the QP; power and drone are
    optimized (Algorithm 1 + SCA, alternated) on the expected cost of its predicted inputs."""

    name = "pid"

    def __init__(self, config: ConfigLike = None, env_id: str = JOINT, seed: int | None = None,
                 gains: PIDGains | Mapping[str, Any] | None = None, **settings: Any):
        super().__init__(config, env_id, seed, **settings)
        self.gains = gains if isinstance(gains, PIDGains) else PIDGains(**dict(gains or {}))
        self.integral = np.zeros((self.config.num_agvs, 2))

    def _on_reset(self, rng: np.random.Generator) -> None:
        super()._on_reset(rng)
        self.integral = np.zeros((self.config.num_agvs, 2))

    def plan(self, snapshot: Snapshot) -> Plan:
        c, g = self.config, self.gains
        increments, integral = pid_rollout(
            snapshot.x_aug, snapshot.reference, self.integral, self.solver.model, g,
            c.control.accel_max_mps2, c.control.accel_increment_max_mps2, commands=self._commands(snapshot),
        )
        self.integral = integral  # the integrator advances with the step that is sent
        return self.solver.solve(snapshot, blocks=("power", "drone"), increments=increments)


class LQRPolicy(AOPolicy):
    """Predictive LQR: the fixed infinite-horizon gain of the same DARE (Q1, Q2) replaces the QP;
    power and drone are optimized on the expected cost of its predicted inputs."""

    name = "lqr"

    def __init__(self, config: ConfigLike = None, env_id: str = JOINT, seed: int | None = None, **settings: Any):
        super().__init__(config, env_id, seed, **settings)
        self.gain = lqr_gain(self.solver.model)

    def plan(self, snapshot: Snapshot) -> Plan:
        c = self.config
        increments = lqr_rollout(snapshot.x_aug, snapshot.reference, self.solver.model, self.gain,
                                 c.control.accel_max_mps2, c.control.accel_increment_max_mps2,
                                 commands=self._commands(snapshot))
        return self.solver.solve(snapshot, blocks=("power", "drone"), increments=increments)


class RGMPCPolicy(PlannerPolicy):
    """The package's best expert: the reduced problem min Phi(p, q) = sum V_k(psi_k) solved directly
    (coarse exact search, then projected gradient with envelope derivatives; agents.rg_mpc)."""

    name = "rg-mpc"

    def _make_solver(self, **settings: Any) -> Planner:
        return ReducedGradientPlanner(self.config, ReducedSettings(**settings))


class DVMPCPolicy(PlannerPolicy):
    """The delivery-value expert (agents.dv_mpc.DeliveryValuePlanner): each command planned as if it
    arrives (the psi = 1 MPC), power and the drone chosen to maximise the expected worth of the
    commands delivered, ``sum_k psi_k (V_k^lost - V_k^del)``, the future after each command priced
    under loss (its ``tail``). It plans (p, q) for the increments the AGVs apply: on ``lawn/Comm-v1``
    under the paper's law (``control.law="paper"``, the env's AGVs apply the psi-scaled QP) that is the
    paper's problem: it plans as ``rg-mpc`` (its settings are then :class:`~agents.ReducedSettings`);
    under ``"delivery"`` with the loss-aware tail, under ``"delivery-certainty-equivalent"`` with the
    certainty-equivalent one. On ``lawn/Joint-v1`` the tail defaults to the actuator's: loss-aware
    under the hold, certainty-equivalent under ``control.actuator="buffer"`` (the buffer plays a
    delivered plan through later losses), where V^lost plays the buffer's next increment."""

    name = "dv-mpc"

    def _make_solver(self, **settings: Any) -> Planner:
        law = self.config.control.law
        if self.env_id == COMM and law == "paper":
            return ReducedGradientPlanner(self.config, ReducedSettings(**settings))
        if self.env_id == COMM:  # the AGVs apply the law's increments: plan with its tail
            tail = "loss-aware" if law == "delivery" else "certainty-equivalent"
            if settings.get("tail", tail) != tail:
                raise ValueError(f"tail={settings['tail']!r}: on {COMM} the AGVs apply control.law={law!r}, whose "
                                 f"command is the {tail} tail's (plan with tail={tail!r}, or set control.law)")
            settings = {**settings, "tail": tail}
        elif self.config.control.actuator == "buffer":  # the buffer plays the plan through later losses
            settings = {"tail": _CERTAINTY_EQUIVALENT, **settings}
        return DeliveryValuePlanner(self.config, DeliverySettings(**settings))


class DVMPCCertaintyEquivalentPolicy(DVMPCPolicy):
    """``dv-mpc`` with the certainty-equivalent tail (``tail="certainty-equivalent"``): every later command
    priced as delivered, the expert before the loss-aware tail (MODEL.md §4), kept by name for
    comparisons and for the agents built on it."""

    name = "dv-mpc-ce"

    def _make_solver(self, **settings: Any) -> Planner:
        if settings.get("tail", _CERTAINTY_EQUIVALENT) != _CERTAINTY_EQUIVALENT:
            raise ValueError(f"tail={settings['tail']!r}: {self.name} is dv-mpc with tail='certainty-equivalent' "
                             "(use dv-mpc for another tail)")
        return super()._make_solver(**{**settings, "tail": _CERTAINTY_EQUIVALENT})


_CERTAINTY_EQUIVALENT = "certainty-equivalent"


class GlobalMPCPolicy(PlannerPolicy):
    """The global reference (fine tabulated search, exact power split, exact polish): seconds per
    slot, for measuring optimality gaps at small K."""

    name = "global-mpc"

    def _make_solver(self, **settings: Any) -> Planner:
        return GlobalPlanner(self.config, GlobalSettings(**settings))


#: The built-in policies, in the order of every list of them (the command line's, the tables' rows).
BUILT_IN_POLICIES = (
    PolicyEntry("dv-mpc", DVMPCPolicy, "expert", "the delivery-value expert: commands planned as if they arrive, "
                "power and drone spent where delivery is worth most (MODEL.md §4, \"Planning under delivery\")",
                table=True, suite=True),
    PolicyEntry("dv-mpc-ce", DVMPCCertaintyEquivalentPolicy, "expert",
                "dv-mpc with the certainty-equivalent tail (the expert before the loss-aware tail)"),
    PolicyEntry("rg-mpc", RGMPCPolicy, "expert",
                "the paper's per-slot problem solved exactly: the reduced problem over (p, q)",
                table=True, suite=True, experiments=True),
    PolicyEntry("ao-mpc", AOMPCPolicy, "expert", "the paper's joint optimization (AO of control QPs, Algorithm 1, SCA)",
                table=True, paper=True, suite=True, experiments=True),
    PolicyEntry("epa", EPAPolicy, "baseline",
                "equal power allocation; MPC control and drone optimization as the expert",
                table=True, paper=True, suite=True),
    PolicyEntry("sf", SFPolicy, "baseline", "straight flight at a seeded random speed; MPC control and PGD power",
                table=True, paper=True, suite=True),
    PolicyEntry("pid", PIDPolicy, "baseline",
                "predictive PID tracking law; power and drone optimized on its predictions",
                table=True, paper=True, suite=True),
    PolicyEntry("lqr", LQRPolicy, "baseline", "predictive LQR (the DARE gain); power and drone optimized likewise",
                table=True, paper=True, suite=True),
    PolicyEntry("heuristic", HeuristicPolicy, "baseline",
                "scripted PD tracking, distance-proportional power, centroid-seeking drone", suite=True),
    PolicyEntry("global-mpc", GlobalMPCPolicy, "reference",
                "the global reference for optimality gaps (fine search; seconds per slot)"),
)
for _entry in BUILT_IN_POLICIES:
    register(_entry)

#: The paper's comparison: the expert and its four baselines.
PAPER_POLICIES = Names("paper")
#: What ``lawn benchmark`` compares by default (the README's table): the package's best expert, the paper's
#: per-slot problem solved exactly, and the paper's set.
BENCHMARK_POLICIES = Names("table")


def attach_residual(policy: Policy, settings: Mapping[str, Any] | None, clock: DecisionClock | None = None) -> Policy:
    """``policy`` (a trained :class:`~agents.learned.SB3Policy`) acting by the residual scheme its run
    recorded, ``{"anchor": NAME, "scale": s, "moves": [...]}`` (:mod:`agents.residual`), the anchor built for the
    policy's scenario (timed on ``clock`` when given); ``None``: the policy as it is."""
    if settings is None:
        return policy
    checked = check_residual(settings)
    anchor = make_policy(checked["anchor"], policy.config, env_id=policy.env_id)
    if clock is not None:
        anchor = clock.timed(anchor)
    interface = getattr(policy, "interface", None)
    with_residual = getattr(policy, "with_residual", None)
    if with_residual is None:
        raise ValueError(f"{policy.name} records a residual scheme but cannot act by one")
    wrapped: Policy = with_residual(ResidualActions(anchor, policy.config, policy.env_id, interface, checked["scale"],
                                                    checked.get("moves", PARTS)))
    return wrapped


def policy_names() -> list[str]:
    return list(POLICIES)


#: Prefixes of learned agents' names (agents.learned.LOADERS): run directories and shipped agents.
LEARNED_PREFIXES = tuple(LOADERS)


def is_policy_name(name: str) -> bool:
    """True for registered names and for ``sb3:DIR`` / ``bc:DIR`` / ``marl:DIR`` / ``zoo:NAME``."""
    return name in POLICIES or (":" in name and name.split(":", 1)[0] in LEARNED_PREFIXES)


def make_policy(name: str, config: ConfigLike = None, env_id: str | None = None,
                seed: int | None = None, **kwargs: Any) -> Policy:
    """Build a registered policy for ``config`` (a config, a preset name, a dict; default: the default
    scenario, ``gym.make(env_id)``'s) driving ``env_id``.

    ``env_id`` defaults to ``lawn/Joint-v1`` (for trained agents: the env they were trained on). A
    learned agent is built for ``config`` too, and refused where ``config`` differs from its training
    scenario in a setting its network is tied to (:func:`agents.learned.check_scenario`: the law, the
    actuator, the horizon, a fixed fleet size); ``config=trained_config(name)`` builds it on its own.
    Unknown names raise ``ValueError`` listing the valid ones; unknown or invalid settings raise
    ``ValueError`` naming the setting.
    """
    if isinstance(name, str) and ":" in name:
        prefix, path = name.split(":", 1)
        if prefix not in LOADERS:
            raise ValueError(f"unknown policy prefix {prefix!r} in {name!r}; valid: {learned_name_forms()}")
        # no config: the default scenario, as for every policy; an agent trained elsewhere is refused there
        # (agents.learned.check_scenario), and config=trained_config(name) builds it on its own scenario
        policy = LOADERS[prefix](path, resolve_config(config), env_id=env_id, seed=seed, **kwargs)
        return attach_residual(policy, getattr(policy, "residual_settings", None))
    env_id = env_id or JOINT
    try:
        entry = POLICIES[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown policy {name!r}; valid policies: {', '.join(POLICIES)}, "
                         f"or {learned_name_forms()} for trained agents") from None
    if env_id not in entry.env_ids:  # the entry's envs (a Policy class checks its own alike)
        raise ValueError(f"policy {name!r} drives {', '.join(entry.env_ids)}; got env_id={env_id!r}")
    return entry.factory(config, env_id=env_id, seed=seed, **kwargs)
