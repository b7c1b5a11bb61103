"""``rg-mpc``, the paper's per-slot problem solved exactly (MODEL.md §4): the reduced problem
min Phi(p, q) = sum_k V_k(psi_k) (:class:`agents.reduced.ReducedProblem`) searched on a coarse table,
then refined on the exact Phi.

The coarse stage tabulates each V_k at a few psi points with exact QPs, searches a coarse drone grid of
the disc ∩ area with the power budget split exactly on a coarse power grid (min-plus DP, compiled:
:func:`agents.search.grid_search`) and picks the best start among that point, the previous slot's solution
continued and equal power at hover, by exact Phi. The start is refined by projected gradient with Armijo
backtracking and Barzilai-Borwein steps on the exact Phi, alternating p and q, each evaluation K
warm-started QPs (:meth:`agents.reduced.ReducedProblem.refine`).
"""

from __future__ import annotations

import time
from typing import Annotated

import numpy as np
from pydantic import Field
from pydantic.dataclasses import dataclass as pydantic_dataclass

from lawn_env.config import ScenarioConfig
from lawn_env.core import Snapshot
from lawn_env.errors import raises_config_errors

from .optim import disc_box_grid, project_disc_box
from .problem import Plan
from .reduced import SETTINGS_CONFIG, Evaluation, ReducedPlannerBase, ReducedProblem, SearchSettings

__all__ = ["ReducedSettings", "ReducedGradientPlanner"]


@raises_config_errors(noun="setting")
@pydantic_dataclass(frozen=True, config=SETTINGS_CONFIG)
class ReducedSettings(SearchSettings):
    """Resolution and iteration budget of ``rg-mpc``."""

    psi_points: Annotated[int, Field(ge=2)] = 9
    """psi grid points (uniform on [0, 1]) of the tabulated V_k used to pick the starting point."""


class ReducedGradientPlanner(ReducedPlannerBase):
    """``rg-mpc``: coarse tabulated search, then projected gradient on the exact Phi."""

    settings_class = ReducedSettings
    settings: SearchSettings  # ReducedSettings, or a search's settings of its own

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
