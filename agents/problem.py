"""What both experts share (:mod:`agents.ao`, the paper's AO, and :mod:`agents.reduced`, the
reduction the reduced-problem planners share): one slot's planning problem (:class:`SlotProblem`: the snapshot's
state, the slot's QP data, the planning link and the feasible sets; evaluates J^ and its pieces),
the coefficients of J^ per AGV, and the plan a planner returns (:class:`Plan`)."""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from lawn_env import channel
from lawn_env.config import ScenarioConfig
from lawn_env.core import Snapshot
from lawn_env.dynamics import POSITION, cost_coefficients
from lawn_env.mpc import OutageAwareMPC, SlotData

__all__ = ["Plan", "Coefficients", "SlotProblem"]


@dataclass(frozen=True)
class Plan:
    """One slot's decision and how it was reached.

    ``objective_trace`` has one row per AO iteration and one column per block (control, power,
    drone): J^ after that block; NaN where a block is not run (baselines fix some blocks).
    When the control block is optimized together with power or the drone, the solver ends with
    one more control block at the returned (p, q), so ``increments`` are the exact QP optimum
    there; ``objective`` is J^ after it (at most the trace's last entry, which is kept in
    ``info["objective_before_final_qp"]``).
    """

    increments: np.ndarray  # (K, N_p, 2), m/s^2; the first row is sent
    power_w: np.ndarray  # (K,)
    drone_position: np.ndarray  # (2,), q[n]
    objective: float  # J^ at the returned point
    objective_trace: np.ndarray  # (iterations, 3)
    iterations: int
    solve_time_s: float
    info: dict[str, Any] = field(default_factory=dict)


#: L, S, W of J^_k = L psi^2 + 2 S psi + W per AGV (paper, P4), each (K,).
Coefficients = tuple[np.ndarray, np.ndarray, np.ndarray]


class SlotProblem:
    """One slot's planning problem, the shape both experts share: the snapshot's state, the slot's
    QP data (the planner's warm-started MPC), the planning link and the slot's feasible sets (power
    budget, the drone's reach from where it is, the area); evaluates J^ and its pieces.

    ``config`` is the planner's own, the one its ``mpc`` and ``link`` were built from, not the
    snapshot's: the sizes, the power budget, the drone's reach V_max Δτ and the area are those of the
    system it plans for (a planner built for another drone speed than the environment's plans the
    moves of the drone it was built for). ``moves``: the slots the drone moves before the decision
    acts (its reach is that many slots'; ``dv-mpc`` under a control period)."""

    def __init__(self, mpc: OutageAwareMPC, link: channel.LinkParams, snapshot: Snapshot, config: ScenarioConfig,
                 state: np.ndarray | None = None, moves: int = 1):
        self.mpc = mpc
        self.link = link
        # x~ as the planner estimates it (``state``: a tracker's, with the applied acceleration after
        # x~ for a lag-aware MPC), else as observed
        self.x_aug = np.asarray(snapshot.x_aug if state is None else np.asarray(state)[:, :6], dtype=float)
        self.reference = np.asarray(snapshot.reference, dtype=float)
        self.q_prev = np.asarray(snapshot.drone_position, dtype=float)
        k, window = config.num_agvs, config.control.horizon + 1
        if self.x_aug.shape != (k, 6) or self.reference.shape != (k, window, 6):
            raise ValueError(
                f"snapshot shapes x_aug {self.x_aug.shape}, reference {self.reference.shape}; expected "
                f"({k}, 6) and ({k}, {window}, 6) for this config"
            )
        self.agv_xy = self.x_aug[:, POSITION]
        self._state = self.x_aug if state is None else np.asarray(state, dtype=float)
        self._slot = snapshot.slot
        self.budget = config.power_budget_w
        self.reach = float(config.drone_reach_m) * moves  # the drone's reach over ``moves`` slots
        self.area = config.area_m

    @functools.cached_property
    def data(self) -> SlotData:
        """The slot's QP data (:meth:`lawn_env.mpc.OutageAwareMPC.prepare`), prepared on first use (a
        problem whose values come from elsewhere never needs it)."""
        return self.mpc.prepare(self._state, self.reference, self._slot)

    # ------------------------------------------------------------------ pieces of J^
    def coefficients(self, dmu: np.ndarray) -> Coefficients:
        """L, S, W of J^_k = L psi^2 + 2 S psi + W for increments ``dmu`` (K, N_p, 2) (paper, P4)."""
        return cost_coefficients(self.mpc.model, self.data.linear, self.data.constant, dmu)

    def distance_sq(self, q: np.ndarray) -> np.ndarray:
        return self.link.distance_sq(q, self.agv_xy)

    def success(self, power_w: np.ndarray, q: np.ndarray) -> np.ndarray:
        return self.link.success_sq(power_w, self.distance_sq(q))

    def objective(self, dmu: np.ndarray, power_w: np.ndarray, q: np.ndarray) -> float:
        lcoef, scoef, wcoef = self.coefficients(dmu)
        psi = self.success(power_w, q)
        return float(np.sum(lcoef * psi * psi + 2.0 * scoef * psi + wcoef))
