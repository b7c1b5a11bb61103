"""``dv-mpc``, the delivery-value expert (MODEL.md §4, "Planning under delivery"), for one scenario or a
batch of them.

A command acts only if it arrives and a lost one is seen and replanned at the next slot, so each AGV's
expected cost is linear in its success probability: ``V_k(psi) = V_k^lost - psi w_k``
(:class:`DeliveryProblem`). Two QPs per AGV and slot give ``V^del`` and ``V^lost`` (the
loss-aware tail's, :class:`lawn_env.tail.LossAwareTail`, or the certainty-equivalent MPC's); the drone's
position and the power split then maximise ``sum_k psi_k w_k`` by the compiled search and refinement
of :func:`agents.search.delivery_decisions`.

:class:`DeliveryValuePlanner` plans B scenarios at once (:meth:`~DeliveryValuePlanner.plan_scenarios`):
their QPs in one stack per psi-bar and slot phase, each scenario warm-started from its own last solve,
their searches in one compiled call. Each scenario keeps what it carries across slots (the tracker,
psi-bar, the previous decision), so a scenario of a batch decides exactly as it does alone; a single
decision (:meth:`~DeliveryValuePlanner.plan`) is the batch of one. Its settings are
:class:`DeliverySettings`; the reduction it shares with ``rg-mpc`` and ``global-mpc`` is :mod:`agents.reduced`'s.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Annotated, Literal

import numpy as np
from pydantic import Field
from pydantic.dataclasses import dataclass as pydantic_dataclass

from lawn_env import channel
from lawn_env.config import ScenarioConfig
from lawn_env.core import Snapshot
from lawn_env.errors import raises_config_errors
from lawn_env.mpc import MPCSolution, OutageAwareMPC, Rows
from lawn_env.tail import (
    BOUNDS_PROBABILITY,
    DELIVERY_MEMORY,
    DELIVERY_START_ITERATIONS,
    LossAwareTail,
    expected_delivery,
)

from . import search
from .estimation import AGVTracker
from .optim import project_disc_box
from .problem import Plan
from .reduced import SETTINGS_CONFIG, Evaluation, ReducedPlannerBase, ReducedProblem, SearchSettings

__all__ = ["DeliveryProblem", "DeliverySettings", "DeliveryValuePlanner"]


class DeliveryProblem(ReducedProblem):
    """One slot's problem under delivery (MODEL.md §4, "Planning under delivery"):

        Phi(p, q) = sum_k psi_k V_k^del + (1 - psi_k) V_k^lost = sum_k V_k^lost - psi_k(p_k, q) w_k,

    ``V^del`` the MPC's value with every planned increment delivered (psi = 1), ``V^lost`` the same
    with the next command lost (:meth:`lawn_env.mpc.OutageAwareMPC.delivery_values`: held at zero, or
    under the buffered actuator the increment its buffer plays, ``snapshot.buffer``) and
    ``w = V^lost - V^del >= 0`` what delivering AGV k's command is worth. The increments are the
    psi = 1 solution's at every (p, q). Two QPs per AGV when it is built; an evaluation after that
    is the channel alone."""

    def __init__(self, mpc: OutageAwareMPC, link: channel.LinkParams, snapshot: Snapshot, config: ScenarioConfig,
                 state: np.ndarray | None = None, values: tuple[MPCSolution, np.ndarray] | None = None,
                 moves: int = 1):
        super().__init__(mpc, link, snapshot, config, state, moves)
        # (V^del's solution, V^lost): the certainty-equivalent MPC's unless given (the loss-aware tail's)
        self.delivered, self.lost = mpc.delivery_values(self.data, snapshot.buffer) if values is None else values
        self.worth = self.lost - self.delivered.value  # w_k >= 0

    def values_at_psi(self, psi: np.ndarray) -> tuple[np.ndarray, np.ndarray, MPCSolution]:
        """V_k(psi_k) = V^lost - psi w and its slope -w, exactly, for psi (..., K); the solution is
        the psi = 1 one whatever psi."""
        psi = np.asarray(psi, dtype=float)
        return self.lost - psi * self.worth, np.broadcast_to(-self.worth, psi.shape), self.delivered


@raises_config_errors(noun="setting")
@pydantic_dataclass(frozen=True, config=SETTINGS_CONFIG)
class DeliverySettings(SearchSettings):
    """Resolution and iteration budget of ``dv-mpc`` (meanings as in :class:`agents.rg_mpc.ReducedSettings`; no psi
    table: its values are linear in psi). An evaluation costs no QP, so it refines longer."""

    refine_iterations: Annotated[int, Field(ge=0)] = 8
    model_lag: bool = True
    """Predict with the actuator lag the config declares (``disturbance.actuator_lag_s``): the MPC's
    state is x~ and the acceleration the AGV applied, which the planner follows from the commanded
    accelerations it observes (:class:`agents.estimation.AGVTracker`). Without a lag, no change."""
    filter_measurements: bool = True
    """Plan from a Kalman filter's positions and velocities where the config declares measurement
    noise (``disturbance.measurement_noise_*``; :class:`agents.estimation.AGVTracker`), not from each
    noisy measurement. Without measurement noise, no change."""
    tail: Literal["loss-aware", "certainty-equivalent"] = "loss-aware"
    """How the future after the command is priced (MODEL.md §4): ``"loss-aware"``, every later command
    delivered with the expected delivery psi-bar and replanned (:class:`lawn_env.tail.LossAwareTail`:
    the modified Riccati recursion, the command planned as delivered for one step);
    ``"certainty-equivalent"``, every later command delivered (the psi = 1 MPC over the horizon and
    the DARE behind it: the expert before the loss-aware tail, which diverges where links lose most
    commands)."""
    bounds_probability: Annotated[float, Field(gt=0, le=1)] = BOUNDS_PROBABILITY
    """The loss-aware tail keeps the bounds of the j-th later command of its plan while
    ``psi-bar**j`` is at least this (:class:`lawn_env.tail.LossAwareTail`: where the all-delivered path
    is unlikely its bounds would bind where no AGV will be); the next command's bounds always hold."""
    delivery_memory: Annotated[float, Field(ge=0, lt=1)] = DELIVERY_MEMORY
    """The loss-aware tail's psi-bar: ``memory * psi-bar + (1 - memory) * sum_k psi_k w_k / sum_k w_k``
    after each slot (:func:`lawn_env.tail.expected_delivery`), from 1 at the episode's start."""
    delivery_weights: Literal["worth", "uniform"] = "worth"
    """What psi-bar averages the AGVs' success probabilities by: ``"worth"``, what delivering each
    command is worth (the commands that matter; the default), or ``"uniform"``, the fleet's plain
    average (docs/experts.md measures both)."""
    delivery_start_iterations: Annotated[int, Field(ge=0, le=20)] = DELIVERY_START_ITERATIONS
    """psi-bar at the episode's first slot: this many fixed-point steps from 1 (each the search at
    psi-bar, then its worth-weighted success); 0 starts from 1."""
    terminal_success: Annotated[float, Field(gt=0, le=1)] = 1.0
    """The certainty-equivalent tail's terminal weight: 1, the loss-free DARE's (the paper's Q3); below 1,
    the modified Riccati equation's at that success probability behind stages priced as delivered
    (docs/experts.md: measured, not adopted; ``tail="certainty-equivalent"`` only)."""

    def __post_init__(self) -> None:
        if self.tail == "loss-aware" and self.terminal_success != 1.0:
            raise ValueError(f"terminal_success={self.terminal_success!r}: a terminal weight of the certainty-"
                             "equivalent tail; with tail='loss-aware' every stage is priced at the expected "
                             "delivery (set tail='certainty-equivalent' to use it)")


@dataclass
class _Scenario:
    """What one scenario's planning carries from slot to slot."""

    tracker: AGVTracker
    psi_bar: float | None = None  # the loss-aware tail's expected delivery; None: the episode's start
    last: tuple[np.ndarray, np.ndarray] | None = None  # the previous slot's (power, drone move)
    worth: np.ndarray = field(default_factory=lambda: np.zeros(0))


class DeliveryValuePlanner(ReducedPlannerBase):
    """``dv-mpc``: the delivery problem's search and refinement (module docstring). The increments are the
    psi = 1 MPC's; power and the drone maximise ``sum_k psi_k w_k``, the expected worth of the commands
    delivered.

    With commands every P slots (a control period the planner knows, MODEL.md §7) the command is the
    increment of the next command slot, held P slots, and ``w`` its worth. On a slot without a command
    nothing is sent: the drone serves the next command, planned from where it could be by then (the
    reach of the moves until that slot, this one included), and this slot's move heads straight for it
    (``info["command_position"]``)."""

    settings_class = DeliverySettings
    settings: DeliverySettings

    def __init__(self, config: ScenarioConfig, settings: DeliverySettings | None = None):
        super().__init__(config, settings)
        s = self.settings
        self.tail = (LossAwareTail.from_config(config, self._lag(), s.bounds_probability, s.qp_backend)
                     if s.tail == "loss-aware" else None)
        self.period = self.mpc.control_period
        self.scenarios: list[_Scenario] = []  # one per scenario of the batch it plans (set by its first call)

    def _lag(self) -> bool:
        """Whether the planner predicts with the config's actuator lag (``model_lag`` and a lag to model)."""
        return bool(self.settings.model_lag and self.config.disturbance.actuator_lag_s > 0)

    def _make_mpc(self) -> OutageAwareMPC:
        """The psi = 1 MPC with the settings' terminal weight, predicting with the lag where modelled."""
        s = self.settings
        return OutageAwareMPC.from_config(self.config, backend=s.qp_backend, terminal_success=s.terminal_success,
                                          lag=self._lag())

    def _scenario(self) -> _Scenario:
        return _Scenario(AGVTracker(self.config, lag=self._lag(), filter=self.settings.filter_measurements))

    # ------------------------------------------------------------------ one scenario's view
    def _first(self) -> _Scenario:
        """The first scenario's state; before any plan, a fresh one (not kept: reading it sets no batch size)."""
        return self.scenarios[0] if self.scenarios else self._scenario()

    @property
    def batches(self) -> bool:
        """True when more than one scenario may be planned at once: each keeps its own warm starts only with
        the compiled QP backend (the reference backends keep one workspace per stack position)."""
        return self.settings.qp_backend == "compiled"

    @property
    def tracker(self) -> AGVTracker:
        """The (first) scenario's tracker (:class:`agents.estimation.AGVTracker`)."""
        return self._first().tracker

    @property
    def psi_bar(self) -> float | None:
        """The (first) scenario's expected delivery (None at an episode's start)."""
        return self._first().psi_bar

    @property
    def last(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The (first) scenario's previous decision: (power, drone move), None at an episode's start."""
        return self._first().last

    # ------------------------------------------------------------------ episodes
    def reset(self, which: np.ndarray | None = None) -> None:
        """New episodes: every scenario's (the next call may plan another number of them), or those of
        the boolean mask ``which`` over the batch (the others continue)."""
        if which is None:
            super().reset()
            if self.tail is not None:
                self.tail.reset()
            self.scenarios = []
            return
        which = np.asarray(which, dtype=bool)
        if which.shape != (len(self.scenarios),):
            raise ValueError(f"which has shape {which.shape}; this planner plays {len(self.scenarios)} scenarios")
        self.mpc.reset(which)
        if self.tail is not None:
            self.tail.reset(which)
        for i in np.flatnonzero(which).tolist():
            self.scenarios[i] = self._scenario()

    def _moves(self, slot: int) -> int:
        """The drone's moves until the next command goes out, the one of this slot included."""
        return 1 + (-int(slot)) % self.period

    # ------------------------------------------------------------------ planning
    def plan(self, snapshot: Snapshot) -> Plan:
        """One scenario's decision: :meth:`plan_scenarios` of one."""
        return self.plan_scenarios([snapshot])[0]

    def plan_scenarios(self, snapshots: Sequence[Snapshot]) -> list[Plan]:
        """The decisions of B scenarios of this planner's config, each from its own episode so far (the
        batch's size is fixed by the first call after a full :meth:`reset`)."""
        start = time.perf_counter()
        if not snapshots:
            raise ValueError("snapshots is empty: plan_scenarios needs one snapshot per scenario")
        if not self.scenarios:
            self.scenarios = [self._scenario() for _ in snapshots]
        if len(snapshots) != len(self.scenarios):
            raise ValueError(f"{len(snapshots)} snapshots for a planner playing {len(self.scenarios)} scenarios: "
                             "one per scenario (reset() to start another batch)")
        if len(snapshots) > 1 and not self.batches:
            raise ValueError(f"qp_backend={self.settings.qp_backend!r} plans one scenario at a time: several at "
                             "once need qp_backend='compiled' (each scenario's own warm starts)")
        problems = self._problems(snapshots)
        decided = search.decide(problems, [s.last for s in self.scenarios], self.settings)
        plans = [self._decision(i, snapshot, problem, decided, start)
                 for i, (snapshot, problem) in enumerate(zip(snapshots, problems, strict=True))]
        elapsed = time.perf_counter() - start
        return [replace(plan, solve_time_s=elapsed / len(plans)) for plan in plans]

    def _decision(self, i: int, snapshot: Snapshot, problem: DeliveryProblem, decided: search.Decisions,
                  start: float) -> Plan:
        """Scenario ``i``'s plan from the batch's decisions; advances what it carries."""
        scenario = self.scenarios[i]
        best = _decided(problem, decided, i)
        scenario.last = (best.power_w.copy(), best.drone_position - problem.q_prev)
        tried = {name: float(decided.start_values[i, j]) for j, name in enumerate(search.STARTS)
                 if math.isfinite(decided.start_values[i, j])}
        plan = self._plan(problem, best, start, {"start": search.STARTS[int(decided.origin[i])],
                                                 "start_values": tried})
        plan.info["qp_evaluations"] = int(decided.evaluations[i])
        if self.tail is not None:
            assert scenario.psi_bar is not None
            plan.info["expected_delivery"] = scenario.psi_bar
            scenario.psi_bar = float(expected_delivery(scenario.psi_bar, best.psi, self._weights(problem.worth),
                                                       self.settings.delivery_memory))
        if self._moves(snapshot.slot) == 1:
            return plan
        target = plan.drone_position  # where the next command goes out from: one move toward it now
        step = project_disc_box(target, np.asarray(snapshot.drone_position, dtype=float),
                                float(self.config.drone_reach_m), self.config.area_m)
        return replace(plan, drone_position=step, info={**plan.info, "command_position": target})

    def _problems(self, snapshots: Sequence[Snapshot]) -> list[DeliveryProblem]:
        """Each scenario's delivery problem: V^del and V^lost of the batch (the tail's at each scenario's
        psi-bar, its first slot's by :meth:`_first_delivery`; or the certainty-equivalent MPC's)."""
        states = [self._state(s, snapshot) for s, snapshot in zip(self.scenarios, snapshots, strict=True)]
        everyone = Rows(np.arange(len(snapshots)), len(snapshots))
        z, reference, slots, queue = _stacked(snapshots, states)
        if self.tail is None:
            data = self.mpc.prepare(z, reference, slots if self.period > 1 else None)
            values = self.mpc.delivery_values(data, queue, everyone)
        else:
            unset = np.array([s.psi_bar is None for s in self.scenarios])
            if unset.any():
                self._first_delivery(snapshots, states, np.flatnonzero(unset))
            psi_bar = np.array([s.psi_bar for s in self.scenarios], dtype=float)
            values = self.tail.delivery_values(z, reference, psi_bar, slots, queue, everyone)
        return self._made(snapshots, states, values, range(len(snapshots)))

    def _made(self, snapshots: Sequence[Snapshot], states: Sequence[np.ndarray | None],
              values: tuple[MPCSolution, np.ndarray], rows: Sequence[int]) -> list[DeliveryProblem]:
        """The problems of the scenarios ``rows`` from their values (the batch's leading axis, in order)."""
        delivered, lost = values
        out = []
        for j, i in enumerate(rows):
            mine = MPCSolution(delivered.increments[j], delivered.value[j], delivered.status[j],
                               delivered.iterations[j], delivered.solve_time_s)
            out.append(DeliveryProblem(self.mpc, self.link, snapshots[i], self.config, states[i], (mine, lost[j]),
                                       self._moves(snapshots[i].slot)))
        for i, problem in zip(rows, out, strict=True):
            self.scenarios[i].worth = problem.worth
        return out

    def _first_delivery(self, snapshots: Sequence[Snapshot], states: Sequence[np.ndarray | None],
                        rows: np.ndarray) -> None:
        """psi-bar at the first slot of the scenarios ``rows`` (:func:`lawn_env.tail.first_delivery`, all
        of them in lockstep): ``delivery_start_iterations`` fixed-point steps from 1, each the search's
        (p, q) at the step's psi-bar and its worth-weighted success."""
        tail = self.tail
        assert tail is not None
        picked = [snapshots[i] for i in rows.tolist()]
        z, reference, slots, queue = _stacked(picked, [states[i] for i in rows.tolist()])
        psi_bar = np.ones(rows.size)
        for _ in range(self.settings.delivery_start_iterations):
            values = tail.delivery_values(z, reference, psi_bar, slots, queue, Rows(rows, len(snapshots)))
            problems = self._made(snapshots, states, values, rows.tolist())
            psi = search.decide(problems, [None] * rows.size, self.settings, search_only=True).psi
            weights = np.stack([self._weights(p.worth) for p in problems])
            psi_bar = expected_delivery(psi_bar, psi, weights, 0.0)
        for j, i in enumerate(rows.tolist()):
            self.scenarios[i].psi_bar = float(psi_bar[j])

    def _state(self, scenario: _Scenario, snapshot: Snapshot) -> np.ndarray | None:
        """The MPC's state from the scenario's tracker (:class:`agents.estimation.AGVTracker`: filtered
        under measurement noise, the applied acceleration appended under a lag); None when it has nothing
        to add (the observed x~ as it is)."""
        if scenario.tracker.lag_alpha is None and not scenario.tracker.filtering:
            return None
        return scenario.tracker.state(snapshot.x_aug)

    def _weights(self, worth: np.ndarray) -> np.ndarray:
        """psi-bar's weights of the AGVs (``delivery_weights``): their worth, or all alike."""
        return worth if self.settings.delivery_weights == "worth" else np.ones_like(worth)


def _stacked(snapshots: Sequence[Snapshot], states: Sequence[np.ndarray | None]
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """The batch's MPC states (the trackers' where they have one, else x~), references (B, K, N_p+1, 6),
    slots (B,) and buffered actuator queues (B, K, L, 2; None under the hold)."""
    z = np.stack([np.asarray(snap.x_aug if state is None else state, dtype=float)
                  for snap, state in zip(snapshots, states, strict=True)])
    reference = np.stack([np.asarray(snap.reference, dtype=float) for snap in snapshots])
    slots = np.array([int(snap.slot) for snap in snapshots], dtype=np.int64)
    queue = None if snapshots[0].buffer is None else np.stack([np.asarray(s.buffer, dtype=float) for s in snapshots])
    return z, reference, slots, queue


def _decided(problem: DeliveryProblem, decided: search.Decisions, i: int) -> Evaluation:
    """Scenario ``i``'s decision of ``decided`` as an :class:`agents.reduced.Evaluation` of ``problem``."""
    psi = decided.psi[i]
    return Evaluation(float(decided.phi[i]), problem.lost - psi * problem.worth, -problem.worth, psi,
                      problem.delivered.increments, decided.power[i], decided.position[i],
                      problem.delivered.num_fallbacks)
