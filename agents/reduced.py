"""The reduced per-slot problem, the shared reduction of the reduced-problem experts (MODEL.md §4).

For fixed (p, q) the control part splits into one convex QP per AGV whose optimal value V_k
depends on (p, q) only through psi_k = psi(p_k, q). The per-slot problem is therefore

    min over (p, q) of  Phi(p, q) = sum_k V_k(psi_k(p_k, q)),   p in the budget set, q in disc ∩ area,

K + 2 variables, separable in p for fixed q. By the envelope theorem V_k'(psi) is the partial
derivative of J^_k in psi at the QP optimum, ``2 psi L_k + 2 S_k``, free after each solve, so

    dPhi/dp_k = V_k'(psi_k) dpsi_k/dp_k,    dPhi/dq = sum_k V_k'(psi_k) dpsi_k/dq.

This module holds what the planners on it share: :class:`ReducedProblem` (Phi with exact QPs, its
gradient, the projected-gradient refinement and the tabulated grid search), the settings every
planner's search reads (:class:`PlannerSettings`, :class:`SearchSettings`) and their base
(:class:`ReducedPlannerBase`). The planners live in modules named after them:

* :mod:`agents.global_mpc` (``"global-mpc"``, :class:`~agents.global_mpc.GlobalPlanner`): a reference
  for small K. Each V_k is tabulated on a fine psi grid with exact QPs (cubic Hermite with the envelope
  slopes between points); drone positions are searched on a fine grid of the disc ∩ area; for each
  position the power budget is split exactly on a power grid by min-plus dynamic programming; the best
  point is then polished by projected gradient on the exact Phi and its value is the exact Phi there
  (the QPs re-solved at the returned (p, q)). Too slow to control with: it measures optimality gaps.
* :mod:`agents.rg_mpc` (``"rg-mpc"``, :class:`~agents.rg_mpc.ReducedGradientPlanner`): the fast expert.
  The same pipeline at a coarse resolution (a few psi points, a coarse drone grid, a coarse power grid)
  picks a starting point; it is compared by exact Phi with the previous slot's solution and with equal
  power at hover, and the best is refined by projected gradient with Armijo backtracking and
  Barzilai-Borwein steps on the exact Phi, alternating p and q, each evaluation K warm-started QPs.
* :mod:`agents.dv_mpc` (``"dv-mpc"``, :class:`~agents.dv_mpc.DeliveryValuePlanner`): the same search and
  refinement on the objective of MODEL.md §4, "Planning under delivery": a command acts only if it
  arrives and a lost one is seen and replanned at the next slot, so the increments are the psi = 1 MPC's
  and AGV k's expected cost is ``V_k(psi) = V_k^lost - psi w_k``, linear in psi
  (:class:`~agents.dv_mpc.DeliveryProblem`): two QPs per AGV per slot, then no QP in the search or the
  refinement.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Annotated, Any, Protocol

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

from . import search
from .optim import project_budget, project_disc_box
from .problem import Plan, SlotProblem

__all__ = ["Evaluation", "ReducedProblem", "ValueFunction", "ValueTable", "SETTINGS_CONFIG", "PlannerSettings",
           "SearchSettings", "ReducedPlannerBase"]


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


# ---------------------------------------------------------------------- planners
#: What every planner's settings class is validated with: unknown settings and NaN/inf refused.
SETTINGS_CONFIG = ConfigDict(extra="forbid", allow_inf_nan=False)


@raises_config_errors(noun="setting")
@pydantic_dataclass(frozen=True, config=SETTINGS_CONFIG)
class PlannerSettings:
    """What every reduced-problem planner's search reads (the fields once; each planner's settings
    class, beside its planner, changes their defaults and adds its own)."""

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
@pydantic_dataclass(frozen=True, config=SETTINGS_CONFIG)
class SearchSettings(PlannerSettings):
    """:class:`PlannerSettings` with the coarse stage of the search (``rg-mpc``'s and ``dv-mpc``'s)."""

    coarse_power_levels: Annotated[int, Field(ge=2)] = 12
    """Every grid position is scored with power in units of P_max / coarse_power_levels ..."""
    keep_positions: Annotated[int, Field(ge=1)] = 4
    """... and the best ``keep_positions`` are split finely."""


class ReducedPlannerBase:
    """What the planners on the reduced problem share: their settings (``settings_class()`` when none are
    given: each planner's own), the warm-started MPC, the planning link and the psi grid of their table."""

    settings_class: type[PlannerSettings]
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
