"""What every experiment module shares: the :class:`Experiment` record and its :class:`Tables`, the
constants, sweep specs and reading seeds out of sweep rows (the claims' helpers are :mod:`.claims`',
the plots' :mod:`.plots`', the records of the tables that are not sweeps
:mod:`paper.experiments.rows`')."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Protocol, TypeVar

from agents.registry import Names
from evaluation.sweep import SpecValue, SweepRow, SweepSpec

if TYPE_CHECKING:  # an annotation only: the claims' module is not the records' import
    from .claims import Claim

__all__ = ["Experiment", "Builder", "Tables", "TableRow", "Metric", "EXPERTS", "BASELINES", "REPORT_SLOT", "SEEDS",
           "QUICK_SEEDS", "QUICK_SET", "spec", "slot_cost", "by_seed", "values"]

#: The experts of the paper's figures: the registry's entries with ``experiments=True`` (agents.registry).
EXPERTS = Names("experiments")
BASELINES = ("epa", "pid", "lqr")
#: The paper's "selected time slot" of its rate, blocklength and CE figures.
REPORT_SLOT = 11
#: Episode seeds of every sweep behind a claim (full mode), and in ``--quick`` mode.
SEEDS = 40
QUICK_SEEDS = 2
#: What ``--quick`` sets in every scenario.
QUICK_SET: dict[str, int] = {"num_slots": 30}
#: What a claim or a curve reads off a sweep row: a scalar metric's name, or a function of the row.
Metric = str | Callable[[SweepRow], float]
R = TypeVar("R")


class TableRow(Protocol):
    """A record of a table that is not a sweep (:mod:`paper.experiments.rows`): its cells by column."""

    def as_row(self) -> Mapping[str, object]: ...


@dataclass(frozen=True)
class Builder:
    """A table that is not an episode sweep: its records built (from the output folder and the
    ``--quick`` flag) and one read back from the table's cells."""

    build: Callable[[Path, bool], Sequence[TableRow]]
    read: Callable[[Mapping[str, str]], TableRow]


@dataclass(frozen=True)
class Tables:
    """An experiment's tables by name: its sweeps' rows (``tables[name]``) and its built tables'
    records (:meth:`rows`)."""

    sweeps: Mapping[str, list[SweepRow]] = field(default_factory=dict)
    built: Mapping[str, Sequence[TableRow]] = field(default_factory=dict)

    def __getitem__(self, name: str) -> list[SweepRow]:
        return self.sweeps[name]

    def rows(self, name: str, kind: type[R]) -> list[R]:
        """The records of the built table ``name``, each a ``kind`` (TypeError otherwise)."""
        rows: list[R] = [r for r in self.built[name] if isinstance(r, kind)]
        if len(rows) != len(self.built[name]):
            raise TypeError(f"table {name!r} holds records that are not {kind.__name__}")
        return rows


@dataclass(frozen=True)
class Experiment:
    """One figure of MODEL.md §7 as data: its tables (sweep specs, full and ``--quick``, and
    builders of the tables that are not episode sweeps), a plot that reads only those tables, and
    the function that checks the paper's claims about it on them."""

    name: str
    setting: str  # one line for the settings table of REPRODUCTION.md
    sweeps: Callable[[bool], dict[str, SweepSpec]] = lambda quick: {}  # table name -> sweep spec
    builders: dict[str, Builder] = field(default_factory=dict)  # the tables that are not sweeps
    plot: Callable[[Tables, Path], None] = lambda tables, path: None
    claims: Callable[[Tables], list[Claim]] = lambda tables: []

    def table_names(self, quick: bool = False) -> list[str]:
        return list(self.sweeps(quick)) + list(self.builders)


def spec(name: str, grid: Mapping[str, Sequence[SpecValue]], policies: Sequence[str], quick: bool,
         preset: str = "default", set_: Mapping[str, SpecValue] | None = None) -> SweepSpec:
    """A sweep spec (:func:`evaluation.sweep.run_sweep`) on ``lawn/Joint-v1``: :data:`SEEDS` seeds, or in
    ``--quick`` mode :data:`QUICK_SEEDS` with :data:`QUICK_SET` under ``set_``."""
    return SweepSpec(name=name, env="lawn/Joint-v1", preset=preset,
                     set={**(QUICK_SET if quick else {}), **(set_ or {})}, grid=grid, policies=tuple(policies),
                     seeds=tuple(range(QUICK_SEEDS if quick else SEEDS)))


def slot_cost(row: SweepRow, slot: int = REPORT_SLOT) -> float:
    """The realized stage cost of ``slot`` in an episode (its ``stage_costs``)."""
    costs = row.result.stage_costs
    if costs is None:
        raise ValueError(f"the {row.policy} row of seed {row.seed} does not record its stage costs")
    return float(costs[min(slot, len(costs) - 1)])


def by_seed(rows: Sequence[SweepRow], metric: Metric, policy: str,
            where: Mapping[str, SpecValue] | None = None) -> dict[int, float]:
    """{seed: value} of ``policy``'s rows at the grid values ``where`` (compared as the table's text)."""
    get = metric if callable(metric) else (lambda r: r.metric(metric))
    wanted = {k: str(v) for k, v in (where or {}).items()}
    return {r.seed: get(r) for r in rows
            if r.policy == policy and all(r.grid.get(k) == v for k, v in wanted.items())}


def values(rows: Sequence[SweepRow], key: str) -> list[float]:
    """The sorted distinct values of a numeric grid key."""
    return sorted({float(r.grid[key]) for r in rows})
