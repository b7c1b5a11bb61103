"""``global-mpc``, the global reference for optimality gaps (MODEL.md §4): the reduced problem
(:class:`agents.reduced.ReducedProblem`) solved on fine grids, seconds per slot at small K.

Each V_k is tabulated on a fine psi grid with exact QPs (cubic Hermite with the envelope slopes between
points); every drone position of a fine grid of the disc ∩ area gets the power budget split exactly on a
fine power grid (min-plus DP); the best point is polished by projected gradient on the exact Phi, and its
value is the exact Phi there (the QPs re-solved at the returned (p, q)). Too slow to control with: it
measures how far the experts' decisions are from the best one (``lawn gap``).
"""

from __future__ import annotations

import time
from typing import Annotated

from pydantic import Field
from pydantic.dataclasses import dataclass as pydantic_dataclass

from lawn_env.config import ScenarioConfig
from lawn_env.core import Snapshot
from lawn_env.errors import raises_config_errors

from .optim import disc_box_grid
from .problem import Plan
from .reduced import SETTINGS_CONFIG, PlannerSettings, ReducedPlannerBase, ReducedProblem

__all__ = ["GlobalSettings", "GlobalPlanner"]


@raises_config_errors(noun="setting")
@pydantic_dataclass(frozen=True, config=SETTINGS_CONFIG)
class GlobalSettings(PlannerSettings):
    """Resolution of the global reference ``global-mpc`` (meanings as in :class:`agents.rg_mpc.ReducedSettings`;
    every drone position is split at the full power resolution, no coarse stage)."""

    drone_spacing_m: Annotated[float, Field(gt=0)] = 0.5
    max_drone_points: Annotated[int, Field(ge=1)] = 20_000
    power_levels: Annotated[int, Field(ge=2)] = 200
    refine_iterations: Annotated[int, Field(ge=0)] = 60
    psi_points: Annotated[int, Field(ge=2)] = 401


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
