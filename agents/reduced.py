"""The reduced per-slot problem and the planners built on it (MODEL.md §4).

For fixed (p, q) the control part splits into one convex QP per AGV whose optimal value V_k
depends on (p, q) only through psi_k = psi(p_k, q). The per-slot problem is therefore

    min over (p, q) of  Phi(p, q) = sum_k V_k(psi_k(p_k, q)),   p in the budget set, q in disc ∩ area,

K + 2 variables, separable in p for fixed q. By the envelope theorem V_k'(psi) is the partial
derivative of J^_k in psi at the QP optimum, ``2 psi L_k + 2 S_k``, free after each solve, so

    dPhi/dp_k = V_k'(psi_k) dpsi_k/dp_k,    dPhi/dq = sum_k V_k'(psi_k) dpsi_k/dq.

Two planners use this:

* :class:`GlobalPlanner` (``"global-mpc"``): a reference for small K. Each V_k is tabulated on a
  fine psi grid with exact QPs (cubic Hermite with the envelope slopes between points); drone
  positions are searched on a fine grid of the disc ∩ area; for each position the power budget
  is split exactly on a power grid by min-plus dynamic programming; the best point is then
  polished by projected gradient on the exact Phi and its value is the exact Phi there (the QPs
  re-solved at the returned (p, q)). Too slow to control with: it measures optimality gaps.
* :class:`ReducedGradientPlanner` (``"rg-mpc"``): the fast expert. The same pipeline at a coarse
  resolution (a few psi points, a coarse drone grid, a coarse power grid) picks a starting point;
  it is compared by exact Phi with the previous slot's solution and with equal power at hover,
  and the best is refined by projected gradient with Armijo backtracking and Barzilai-Borwein
  steps on the exact Phi, alternating p and q, each evaluation K warm-started QPs.
* :class:`agents.dv_mpc.DeliveryValuePlanner` (``"dv-mpc"``): the same search and refinement on the
  objective of MODEL.md §4, "Planning under delivery": a command acts only if it arrives and a lost one
  is seen and replanned at the next slot, so the increments are the psi = 1 MPC's and AGV k's expected cost
  is ``V_k(psi) = V_k^lost - psi w_k``, linear in psi (:class:`DeliveryProblem`): two QPs per AGV per
  slot, then no QP in the search or the refinement.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Annotated, Any, Literal, Protocol

import numpy as np
from pydantic import ConfigDict, Field
from pydantic.dataclasses import dataclass as pydantic_dataclass

from lawn_env import channel
from lawn_env.config import ScenarioConfig
from lawn_env.core import Snapshot
from lawn_env.dynamics import cost_coefficients
from lawn_env.errors import raises_config_errors
from lawn_env.mpc import DEFAULT_BACKEND, MPCSolution, OutageAwareMPC
from lawn_env.products import matmul
from lawn_env.tail import (
    BOUNDS_PROBABILITY,
    DELIVERY_MEMORY,
    DELIVERY_START_ITERATIONS,
)

from . import search
from .optim import disc_box_grid, project_budget, project_disc_box
from .problem import Plan, SlotProblem

__all__ = ["ReducedProblem", "ValueTable", "PlannerSettings", "SearchSettings", "ReducedSettings",
           "ReducedGradientPlanner", "GlobalPlanner", "GlobalSettings", "DeliveryProblem",
           "DeliverySettings"]


@dataclass
class Evaluation:
    """Phi at one (p, q) with everything the gradient needs."""

    phi: float
    values: np.ndarray  # V_k (K,)
    slopes: np.ndarray  # V_k'(psi_k) (K,), envelope derivative
    psi: np.ndarray  # (K,)
    increments: np.ndarray  # (K, N_p, 2), the QP solutions
    power_w: np.ndarray
    drone_position: np.ndarray
    fallbacks: int


class ReducedProblem(SlotProblem):
    """Phi(p, q) of one slot, evaluated with exact QPs (the shared, warm-started MPC): the AO's
    slot problem with the controls solved out."""

    def __init__(self, mpc: OutageAwareMPC, link: channel.LinkParams, snapshot: Snapshot, config: ScenarioConfig,
                 state: np.ndarray | None = None, moves: int = 1):
        super().__init__(mpc, link, snapshot, config, state, moves)
        self.evaluations = 0

    # ------------------------------------------------------------------ exact
    def values_at_psi(self, psi: np.ndarray) -> tuple[np.ndarray, np.ndarray, MPCSolution]:
        """V_k(psi_k) and V_k'(psi_k) (envelope) with exact QPs: (..., K), (..., K), solution; ``psi``
        (..., K) with any leading axes (a table's psi values) is one batched solve."""
        sol = self.mpc.solve_prepared(self.data, psi)
        lcoef, scoef, _ = cost_coefficients(self.mpc.model, self.data.linear, self.data.constant, sol.increments)
        return sol.value, 2.0 * psi * lcoef + 2.0 * scoef, sol  # envelope theorem: V' = dJ^/dpsi at z*

    def evaluate(self, power_w: np.ndarray, q: np.ndarray) -> Evaluation:
        self.evaluations += 1
        psi = self.success(power_w, q)
        values, slopes, sol = self.values_at_psi(psi)
        return Evaluation(float(values.sum()), values, slopes, psi, sol.increments, np.array(power_w, dtype=float),
                          np.array(q, dtype=float), sol.num_fallbacks)

    def gradient(self, ev: Evaluation) -> tuple[np.ndarray, np.ndarray]:
        """(dPhi/dp (K,), dPhi/dq (2,)) by the envelope theorem and the analytic dpsi."""
        _, dpsi_dp, dpsi_dq = channel.success_and_gradients(ev.power_w, ev.drone_position, self.agv_xy, self.link)
        return ev.slopes * dpsi_dp, matmul(ev.slopes, dpsi_dq)

    # ------------------------------------------------------------------ refinement
    def refine(self, ev: Evaluation, iterations: int, armijo: float = 1e-4, max_backtracks: int = 20,
               tolerance: float = 1e-10) -> Evaluation:
        """Projected gradient on the exact Phi, alternating a step in p (onto the budget set) and a
        step in q (onto the disc ∩ area), each with Armijo backtracking along the projection arc
        and its own Barzilai-Borwein step. Unlike the paper's AO, every step sees the optimal
        controls (Phi already minimizes over them), and separate steps for p (W) and q (m) avoid
        the ill-conditioning of one joint step. Stops after ``iterations`` rounds or when a round
        improves Phi by less than ``tolerance`` (relative)."""
        steps: dict[str, float | None] = {"p": None, "q": None}
        grad_p, grad_q = self.gradient(ev)
        for _ in range(iterations):
            improved = False
            for block in ("p", "q"):
                g = grad_p if block == "p" else grad_q
                x = ev.power_w if block == "p" else ev.drone_position
                gnorm = math.sqrt(float(matmul(g, g)))
                if gnorm == 0.0 or not math.isfinite(gnorm):  # flat, or under/overflowed at extreme configs
                    continue
                alpha = steps[block] or 0.5 * (self.budget if block == "p" else self.reach) / gnorm
                if not (math.isfinite(alpha) and alpha > 0.0):
                    continue
                accepted = None
                for _ in range(max_backtracks):
                    if block == "p":
                        x_new = project_budget(x - alpha * g, self.budget)
                    else:
                        x_new = project_disc_box(x - alpha * g, self.q_prev, self.reach, self.area)
                    delta = x_new - x
                    if not np.all(np.isfinite(delta)) or float(matmul(delta, delta)) == 0.0:
                        break
                    cand = self.evaluate(x_new, ev.drone_position) if block == "p" else self.evaluate(ev.power_w, x_new)
                    if cand.phi <= ev.phi + armijo * float(matmul(g, delta)):
                        accepted = cand
                        break
                    alpha *= 0.5
                if accepted is None:
                    continue
                new_grad_p, new_grad_q = self.gradient(accepted)
                y = (new_grad_p - grad_p) if block == "p" else (new_grad_q - grad_q)
                sy = float(matmul(delta, y))
                steps[block] = float(matmul(delta, delta)) / sy if sy > 0 else None
                if ev.phi - accepted.phi > tolerance * abs(ev.phi):
                    improved = True
                ev, grad_p, grad_q = accepted, new_grad_p, new_grad_q
            if not improved:
                break
        return ev

    # ------------------------------------------------------------------ tabulated search
    def table(self, psi_grid: np.ndarray | None) -> ValueFunction:
        """V_k and its envelope slope at every psi of ``psi_grid`` for every AGV: one batched solve."""
        assert psi_grid is not None  # the planners of this problem tabulate on psi_points
        psi = np.repeat(np.asarray(psi_grid, dtype=float)[:, None], self.x_aug.shape[0], axis=1)
        values, slopes, _ = self.values_at_psi(psi)
        return ValueTable(psi_grid, values, slopes)

    def grid_search(self, table: ValueFunction, positions: np.ndarray, levels: int, coarse_levels: int | None = None,
                    keep: int = 4) -> tuple[float, np.ndarray, np.ndarray]:
        """Best (p, q) of the tabulated Phi over ``positions`` (n, 2) and power splits in units of
        P_max / levels (exact on that grid, min-plus DP). With ``coarse_levels`` every position is
        first scored on the coarser power grid and only the ``keep`` best are split finely
        (:func:`agents.search.grid_search`, compiled). Returns (value, p, q)."""
        coarse = levels if coarse_levels is None else coarse_levels
        value, power, q = search.grid_search(table.kind, table.grid, table.table, np.ascontiguousarray(self.agv_xy),
                                             np.ascontiguousarray(positions, dtype=float), (levels, coarse, keep),
                                             float(self.budget), self.link.constants)
        return float(value), power, q


class ValueFunction(Protocol):
    """V_k(psi) as the compiled grid search reads it (:func:`agents.search.grid_search`): ``kind``
    (:data:`agents.search.LINEAR` or :data:`agents.search.HERMITE`), ``grid`` and ``table``
    (:class:`ValueTable`)."""

    kind: int
    grid: np.ndarray
    table: np.ndarray


class ValueTable:
    """V_k(psi) on a psi grid with envelope slopes; cubic Hermite interpolation between points."""

    kind = search.HERMITE

    def __init__(self, grid: np.ndarray, values: np.ndarray, slopes: np.ndarray):
        self.grid = np.asarray(grid, dtype=float)
        self.values = values  # (M, K)
        self.slopes = slopes
        self.table = np.ascontiguousarray(np.concatenate([values, slopes]), dtype=float)  # what the search reads

    def __call__(self, psi: np.ndarray) -> np.ndarray:
        """Interpolated V for psi of shape (K,) (:func:`agents.search.hermite`, compiled)."""
        psi = np.asarray(psi, dtype=float)
        k = self.values.shape[1]
        if psi.shape != (k,):
            raise ValueError(f"psi has shape {psi.shape}; expected ({k},), one per AGV")
        out: np.ndarray = search.hermite(self.grid, self.table, psi)
        return out


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


# ---------------------------------------------------------------------- planners
_CFG = ConfigDict(extra="forbid", allow_inf_nan=False)


@raises_config_errors(noun="setting")
@pydantic_dataclass(frozen=True, config=_CFG)
class PlannerSettings:
    """What every reduced-problem planner's search reads (the fields once; each planner's settings
    class below changes their defaults and adds its own)."""

    drone_spacing_m: Annotated[float, Field(gt=0)] = 1.5
    """Spacing of the drone grid over the disc ∩ area for the starting point."""
    max_drone_points: Annotated[int, Field(ge=1)] = 10_000
    """Cap on the drone grid: a larger reach (V_max Δτ) widens the spacing instead (bounded time
    and memory whatever the config; the default reach of 7.5 m needs 81 points)."""
    power_levels: Annotated[int, Field(ge=2)] = 40
    """Units of P_max / power_levels for the exact split of the starting point."""
    refine_iterations: Annotated[int, Field(ge=0)] = 4
    """Rounds of alternating projected-gradient steps (p, then q) on the exact Phi."""
    qp_backend: str = DEFAULT_BACKEND


@raises_config_errors(noun="setting")
@pydantic_dataclass(frozen=True, config=_CFG)
class SearchSettings(PlannerSettings):
    """:class:`PlannerSettings` with the coarse stage of the search (``rg-mpc``'s and ``dv-mpc``'s)."""

    coarse_power_levels: Annotated[int, Field(ge=2)] = 12
    """Every grid position is scored with power in units of P_max / coarse_power_levels ..."""
    keep_positions: Annotated[int, Field(ge=1)] = 4
    """... and the best ``keep_positions`` are split finely."""


@raises_config_errors(noun="setting")
@pydantic_dataclass(frozen=True, config=_CFG)
class ReducedSettings(SearchSettings):
    """Resolution and iteration budget of ``rg-mpc``."""

    psi_points: Annotated[int, Field(ge=2)] = 9
    """psi grid points (uniform on [0, 1]) of the tabulated V_k used to pick the starting point."""


@raises_config_errors(noun="setting")
@pydantic_dataclass(frozen=True, config=_CFG)
class GlobalSettings(PlannerSettings):
    """Resolution of the global reference ``global-mpc`` (meanings as in :class:`ReducedSettings`;
    every drone position is split at the full power resolution, no coarse stage)."""

    drone_spacing_m: Annotated[float, Field(gt=0)] = 0.5
    max_drone_points: Annotated[int, Field(ge=1)] = 20_000
    power_levels: Annotated[int, Field(ge=2)] = 200
    refine_iterations: Annotated[int, Field(ge=0)] = 60
    psi_points: Annotated[int, Field(ge=2)] = 401


@raises_config_errors(noun="setting")
@pydantic_dataclass(frozen=True, config=_CFG)
class DeliverySettings(SearchSettings):
    """Resolution and iteration budget of ``dv-mpc`` (meanings as in :class:`ReducedSettings`; no psi
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


class ReducedPlannerBase:
    settings_class: type[PlannerSettings] = ReducedSettings
    settings: PlannerSettings

    def __init__(self, config: ScenarioConfig, settings: PlannerSettings | None = None):
        self.config = config
        self.settings = settings if settings is not None else self.settings_class()
        self.mpc = self._make_mpc()
        self.link = channel.LinkParams.from_config(config, planning=True)
        points = getattr(self.settings, "psi_points", None)  # dv-mpc's values need no table
        self.psi_grid = np.linspace(0.0, 1.0, points) if points is not None else None

    def _make_mpc(self) -> OutageAwareMPC:
        """The planner's MPC (built once, with its settings' backend)."""
        return OutageAwareMPC.from_config(self.config, backend=self.settings.qp_backend)

    def reset(self) -> None:
        self.mpc.reset()

    def _plan(self, problem: ReducedProblem, best: Evaluation, start: float, info: dict[str, Any]) -> Plan:
        info.update(qp_evaluations=problem.evaluations, success_probability=best.psi,
                    qp_fallbacks=best.fallbacks)
        trace = np.array([[best.phi, math.nan, math.nan]])
        return Plan(increments=best.increments, power_w=best.power_w, drone_position=best.drone_position,
                    objective=best.phi, objective_trace=trace, iterations=1, solve_time_s=time.perf_counter() - start,
                    info=info)


class ReducedGradientPlanner(ReducedPlannerBase):
    """``rg-mpc``: coarse tabulated search, then projected gradient on the exact Phi."""

    settings: SearchSettings  # ReducedSettings (DeliveryValuePlanner: DeliverySettings)

    def __init__(self, config: ScenarioConfig, settings: SearchSettings | None = None):
        super().__init__(config, settings)
        self._last: tuple[np.ndarray, np.ndarray] | None = None  # previous slot's (p, velocity)

    def _search(self, problem: ReducedProblem) -> Evaluation:
        s = self.settings
        table = problem.table(self.psi_grid)
        positions = disc_box_grid(problem.q_prev, problem.reach, problem.area, s.drone_spacing_m, s.max_drone_points)
        _, p, q = problem.grid_search(table, positions, s.power_levels, s.coarse_power_levels, s.keep_positions)
        return problem.evaluate(p, q)

    def reset(self) -> None:
        super().reset()
        self._last = None

    def _problem(self, snapshot: Snapshot) -> ReducedProblem:
        return ReducedProblem(self.mpc, self.link, snapshot, self.config)

    def plan(self, snapshot: Snapshot) -> Plan:
        start = time.perf_counter()
        problem = self._problem(snapshot)
        k = self.config.num_agvs
        starts = {"search": self._search(problem),
                  "equal": problem.evaluate(np.full(k, problem.budget / k), problem.q_prev)}
        if self._last is not None:
            p_last, v_last = self._last
            q_cont = project_disc_box(problem.q_prev + v_last, problem.q_prev, problem.reach, problem.area)
            starts["previous"] = problem.evaluate(p_last, q_cont)
        origin = min(starts, key=lambda name: starts[name].phi)
        best = problem.refine(starts[origin], self.settings.refine_iterations)
        self._last = (best.power_w.copy(), best.drone_position - problem.q_prev)
        return self._plan(problem, best, start, {"start": origin,
                                                 "start_values": {n: e.phi for n, e in starts.items()}})


class GlobalPlanner(ReducedPlannerBase):
    """``global-mpc``: fine tabulated search, exact power split on a grid, exact polish."""

    settings_class = GlobalSettings
    settings: GlobalSettings

    def __init__(self, config: ScenarioConfig, settings: GlobalSettings | None = None):
        super().__init__(config, settings)

    def plan(self, snapshot: Snapshot) -> Plan:
        start = time.perf_counter()
        problem = ReducedProblem(self.mpc, self.link, snapshot, self.config)
        s = self.settings
        table = problem.table(self.psi_grid)
        positions = disc_box_grid(problem.q_prev, problem.reach, problem.area, s.drone_spacing_m, s.max_drone_points)
        grid_value, p, q = problem.grid_search(table, positions, s.power_levels)
        found = problem.evaluate(p, q)
        best = problem.refine(found, s.refine_iterations)
        info = {
            "grid_value": grid_value,  # tabulated Phi at the grid optimum
            "grid_exact_value": found.phi,  # exact Phi (QPs re-solved) at the grid optimum
            "resolution": {"psi_points": s.psi_points, "drone_spacing_m": s.drone_spacing_m,
                           "power_step_w": problem.budget / s.power_levels, "positions": int(positions.shape[0])},
        }
        return self._plan(problem, best, start, info)
