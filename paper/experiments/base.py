"""What every experiment module shares: the :class:`Experiment` record, the constants, sweep specs
and reading seeds out of tables (the claims' helpers are :mod:`.claims`', the plots' :mod:`.plots`')."""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from agents.registry import Names

if TYPE_CHECKING:  # an annotation only: the claims' module is not the records' import
    from .claims import Claim

__all__ = ["Experiment", "EXPERTS", "BASELINES", "REPORT_SLOT", "SEEDS", "QUICK_SEEDS", "QUICK_SET", "spec",
           "slot_cost", "by_seed", "values"]

#: The experts of the paper's figures: the registry's entries with ``experiments=True`` (agents.registry).
EXPERTS = Names("experiments")
BASELINES = ("epa", "pid", "lqr")
#: The paper's "selected time slot" of its rate, blocklength and CE figures.
REPORT_SLOT = 11
#: Episode seeds of every sweep behind a claim (full mode), and in ``--quick`` mode.
SEEDS = 40
QUICK_SEEDS = 2
#: What ``--quick`` sets in every scenario.
QUICK_SET: dict[str, Any] = {"num_slots": 30}
#: An experiment's tables: table name -> its rows.
Tables = dict[str, list[dict[str, Any]]]


@dataclass(frozen=True)
class Experiment:
    """One figure of MODEL.md §7 as data: its tables (sweep specs, full and ``--quick``, and
    builders of the tables that are not episode sweeps), a plot that reads only those tables, and
    the function that checks the paper's claims about it on them."""

    name: str
    setting: str  # one line for the settings table of REPRODUCTION.md
    sweeps: Callable[[bool], dict[str, dict[str, Any]]] = lambda quick: {}  # table name -> sweep spec
    builders: dict[str, Callable[[Path, bool], list[dict[str, Any]]]] = field(default_factory=dict)  # non-sweep tables
    plot: Callable[[dict[str, list[dict[str, Any]]], Path], None] = lambda tables, path: None
    claims: Callable[[dict[str, list[dict[str, Any]]]], list[Claim]] = lambda tables: []

    def table_names(self, quick: bool = False) -> list[str]:
        return list(self.sweeps(quick)) + list(self.builders)


def spec(name: str, grid: dict[str, Any], policies: Sequence[str], quick: bool, preset: str = "default",
         set_: dict[str, Any] | None = None) -> dict[str, Any]:
    """A sweep spec (:func:`evaluation.sweep.run_sweep`) on ``lawn/Joint-v1``: :data:`SEEDS` seeds, or in
    ``--quick`` mode :data:`QUICK_SEEDS` with :data:`QUICK_SET` under ``set_``."""
    return {"name": name, "env": "lawn/Joint-v1", "preset": preset,
            "set": {**(QUICK_SET if quick else {}), **(set_ or {})}, "grid": grid, "policies": list(policies),
            "seeds": QUICK_SEEDS if quick else SEEDS}


def slot_cost(row: Mapping[str, Any], slot: int = REPORT_SLOT) -> float:
    """The realized stage cost of ``slot`` in an episode row (``stage_costs``, a JSON list)."""
    costs = json.loads(row["stage_costs"]) if isinstance(row["stage_costs"], str) else row["stage_costs"]
    return float(costs[min(slot, len(costs) - 1)])


def by_seed(rows: Sequence[Mapping[str, Any]], metric: str | Callable[..., Any], **where: Any) -> dict[int, float]:
    """{seed: value} of the rows matching ``where`` (values compared as strings)."""
    get = metric if callable(metric) else (lambda r: float(r[metric]))
    return {int(r["seed"]): get(r) for r in rows if all(str(r[k]) == str(v) for k, v in where.items())}


def values(rows: Sequence[Mapping[str, Any]], key: str) -> list[float]:
    """The sorted distinct values of a numeric column."""
    return sorted({float(r[key]) for r in rows})
