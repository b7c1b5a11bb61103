"""The records of the experiments' tables that are not episode sweeps (those are
:class:`evaluation.sweep.SweepRow`'s): an episode's positions (:class:`TraceRow`, the path figures'),
the AO's objective over its iterations (:class:`ConvergenceRow`), and ``lawn gap``'s optimality gaps
(:class:`GapRow` per planner and slot, :class:`GapSummary` per planner). Each writes its table's row
(``as_row``: the columns in field order); the figures' tables read theirs back (``from_row``)."""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field

__all__ = ["TraceRow", "ConvergenceRow", "GapRow", "GapSummary"]


@dataclass(frozen=True)
class TraceRow:
    """One position at one slot of a path figure's episode: the case (its label, preset and policy),
    the episode's control cost, whose position (``drone``, ``agv_<i>`` or ``reference_<i>``) and
    where (m)."""

    case: str
    preset: str
    policy: str
    slot: int
    control_cost: float
    who: str
    x: float
    y: float

    def as_row(self) -> dict[str, object]:
        return {"case": self.case, "preset": self.preset, "policy": self.policy, "slot": self.slot,
                "control_cost": self.control_cost, "who": self.who, "x": self.x, "y": self.y}

    @classmethod
    def from_row(cls, cells: Mapping[str, str]) -> TraceRow:
        return cls(cells["case"], cells["preset"], cells["policy"], int(cells["slot"]), float(cells["control_cost"]),
                   cells["who"], float(cells["x"]), float(cells["y"]))


@dataclass(frozen=True)
class ConvergenceRow:
    """The AO's objective J^ after one block (``control``, ``power`` or ``drone``) of one iteration at
    one slot, beside the global reference's and rg-mpc's values at that slot."""

    slot: int
    iteration: int
    block: str
    objective: float
    global_objective: float
    rg_mpc_objective: float

    def as_row(self) -> dict[str, object]:
        return {"slot": self.slot, "iteration": self.iteration, "block": self.block, "objective": self.objective,
                "global_objective": self.global_objective, "rg_mpc_objective": self.rg_mpc_objective}

    @classmethod
    def from_row(cls, cells: Mapping[str, str]) -> ConvergenceRow:
        return cls(int(cells["slot"]), int(cells["iteration"]), cells["block"], float(cells["objective"]),
                   float(cells["global_objective"]), float(cells["rg_mpc_objective"]))


@dataclass(frozen=True)
class GapRow:
    """One planner at one compared slot: its objective and the global reference's, the relative gap,
    both decision times (s), each one's smallest link power as a share of P_max and the powers (W,
    rounded to 1e-6)."""

    seed: int
    slot: int
    policy: str
    objective: float
    global_objective: float
    gap: float
    decision_time_s: float
    global_time_s: float
    min_power_share: float
    global_min_power_share: float
    power_w: tuple[float, ...]
    global_power_w: tuple[float, ...]

    def as_row(self) -> dict[str, object]:
        """The row of ``gap_rows.csv``: the powers as JSON lists."""
        return {"seed": self.seed, "slot": self.slot, "policy": self.policy, "objective": self.objective,
                "global_objective": self.global_objective, "gap": self.gap, "decision_time_s": self.decision_time_s,
                "global_time_s": self.global_time_s, "min_power_share": self.min_power_share,
                "global_min_power_share": self.global_min_power_share, "power_w": json.dumps(list(self.power_w)),
                "global_power_w": json.dumps(list(self.global_power_w))}


@dataclass(frozen=True)
class GapSummary:
    """One planner's gaps: how many slots, the gap's median, p90 and maximum, the median decision
    time (s), on how many slots some link gets less than 5 % of P_max, and on how many slots it is
    worse than each other planner (``worse_than``: planner -> slots)."""

    policy: str
    slots: int
    gap_median: float
    gap_p90: float
    gap_max: float
    decision_time_median_s: float
    slots_with_a_link_below_5pct_power: int
    worse_than: Mapping[str, int] = field(default_factory=dict)

    def as_row(self) -> dict[str, object]:
        """The row of ``gap_summary.csv``: one ``worse_than_<planner>`` column per other planner."""
        return {"policy": self.policy, "slots": self.slots, "gap_median": self.gap_median, "gap_p90": self.gap_p90,
                "gap_max": self.gap_max, "decision_time_median_s": self.decision_time_median_s,
                "slots_with_a_link_below_5pct_power": self.slots_with_a_link_below_5pct_power,
                **{f"worse_than_{other}": n for other, n in self.worse_than.items()}}
