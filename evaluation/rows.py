"""Evaluation results reduced per row of a table, what every table formats (:mod:`.report`): a row is
(task, env, policy) (:data:`Key`); :class:`Statistics` holds each row's :class:`RowStats` (its seeds,
each metric's mean and interval, the decision time, the score), any two rows' comparison
(:class:`Versus`: geometric, paired, per seed, on both test ranges; computed when read) and a
policy's IQM over tasks. :func:`reduce` makes it; :mod:`.stats` holds the statistics themselves."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from .stats import (
    SCORE_VERSION,
    SUMMARY_METRICS,
    Geometric,
    Interval,
    RangeComparison,
    Score,
    aggregate_score,
    compare_ranges,
    costs_of,
    mean_ci,
    paired_difference,
    paired_geometric,
    score_inputs,
    scores_by_policy,
)

if TYPE_CHECKING:
    from .episode import EpisodeResult, Results

__all__ = ["Key", "COST_METRICS", "Versus", "RowStats", "Statistics", "reduce"]

#: A row of a table: (task, env, policy); a result without a task is on ``"default"``.
Key = tuple[str, str, str]
#: The cost metrics every row carries a mean of.
COST_METRICS = ("control_cost", "transient_cost", "sustained_cost")


@dataclass(frozen=True)
class Versus:
    """A row's per-seed control costs against a reference row's, on the seeds both hold: each
    statistic is computed when first read (a table reads what it shows)."""

    costs: Mapping[int, float]
    reference: Mapping[int, float]

    @cached_property
    def geometric(self) -> Geometric:
        """:func:`paired_geometric`: the geometric mean of the cost ratios, its interval, the seeds won."""
        return paired_geometric(self.costs, self.reference)

    @cached_property
    def paired(self) -> Interval:
        """:func:`paired_difference`: the mean relative difference and its 95 % half-width."""
        mean, half, _ = paired_difference(self.costs, self.reference)
        return Interval(mean, half)

    @cached_property
    def relative(self) -> list[float]:
        """The per-seed relative differences (cost - reference) / reference."""
        return [(self.costs[s] - self.reference[s]) / self.reference[s] for s in self.costs if s in self.reference]

    @cached_property
    def ranges(self) -> RangeComparison:
        """:func:`compare_ranges`: per test range, with the tail and the worst seed."""
        return compare_ranges(self.costs, self.reference)


@dataclass(frozen=True)
class RowStats:
    """One row's statistics: its episodes and their control cost per seed, the mean and 95 %
    half-width of each metric of :data:`SUMMARY_METRICS` (NaN for one its results do not record), the
    sums of the costs (:data:`COST_METRICS`), the median of its episodes' decision times (ms) and its
    normalized score (None where the references are not beside it)."""

    key: Key
    episodes: int
    costs: Mapping[int, float]
    means: Mapping[str, Interval]
    totals: Mapping[str, float]
    decision_ms: float
    score: Score | None

    @property
    def seeds(self) -> int:
        return len(self.costs)


class Statistics:
    """Evaluation results reduced per row (:class:`RowStats`, by :data:`Key`), with each row's
    comparisons against any other (:meth:`versus`) and the IQM of a policy's scores over tasks
    (:meth:`aggregate`): what every table formats (:mod:`.report`), computed once per row."""

    def __init__(self, results: Results, version: int = SCORE_VERSION) -> None:
        groups: dict[Key, list[EpisodeResult]] = {}
        for r in results:
            groups.setdefault((r.task or "default", r.env, r.policy), []).append(r)
        scores = scores_by_policy(results, version=version)
        self.rows = {key: _row(key, members, scores.get(key)) for key, members in groups.items()}
        self.inputs = score_inputs(results, version=version)
        self.seeds = sorted({r.seed for r in results})
        self.transient_slots = next((r.transient_slots for r in results if r.transient_slots is not None), None)
        self._versus: dict[tuple[Key, Key], Versus] = {}

    def row(self, task: str, env: str, policy: str) -> RowStats | None:
        return self.rows.get((task, env, policy))

    def envs(self, task: str) -> list[str]:
        """The envs of ``task``'s rows, in the results' order."""
        return list(dict.fromkeys(env for t, env, _ in self.rows if t == task))

    def versus(self, key: Key, reference: Key) -> Versus | None:
        """Row ``key`` against row ``reference`` (None when either has no results)."""
        if key not in self.rows or reference not in self.rows:
            return None
        if (key, reference) not in self._versus:
            self._versus[(key, reference)] = Versus(self.rows[key].costs, self.rows[reference].costs)
        return self._versus[(key, reference)]

    def summary(self, env: str, policies: Sequence[str], task: str = "default", reference: str | None = None
                ) -> list[SummaryRow]:
        """Per policy with results on ``env`` and ``task``, in the order of ``policies``: its episodes, the
        mean and 95 % half-width of each metric of :data:`SUMMARY_METRICS` and its score; with
        ``reference``, each policy against it per seed (the paired mean difference, over two seeds or
        more, and the geometric comparison)."""
        out = []
        for row in (self.rows.get((task, env, p)) for p in policies):
            if row is None:
                continue
            policy, vs = row.key[2], None
            if reference is not None:
                vs = self.versus((task, env, policy), (task, env, reference))
            out.append(SummaryRow(policy, row.episodes, row.means, reference, row.score,
                                  vs.paired if vs is not None and len(vs.relative) > 1 else None,
                                  vs.geometric if vs is not None and policy != reference else None))
        return out

    def aggregate(self, env: str, policy: str, tasks: Sequence[str]) -> Score:
        """:func:`aggregate_score` of ``policy`` on ``env`` over ``tasks``."""
        return aggregate_score({t: self.inputs[(t, env, policy)] for t in tasks if (t, env, policy) in self.inputs})


@dataclass(frozen=True)
class SummaryRow:
    """One policy's line of a summary: its episodes, the mean and 95 % half-width of each metric of
    :data:`SUMMARY_METRICS`, its normalized score (None without its references beside it) and, against
    the summary's ``reference`` (None: no comparison), the mean per-seed relative difference and the
    geometric comparison (None where they are undefined)."""

    policy: str
    episodes: int
    means: Mapping[str, Interval]
    reference: str | None = None
    score: Score | None = None
    paired: Interval | None = None
    geometric: Geometric | None = None

    def as_row(self) -> dict[str, str | int | float]:
        """The row of ``summary.csv``: ``policy``, ``episodes``, ``METRIC`` and ``METRIC_ci95``; with a
        reference ``cost_vs_REF`` and its ``_ci95`` (NaN where undefined), then, for a policy other than
        the reference, ``ratio_vs_REF``, ``ratio_low``, ``ratio_high`` and ``seeds_won``; with a score,
        ``score``, ``score_low`` and ``score_high``."""
        row: dict[str, str | int | float] = {"policy": self.policy, "episodes": self.episodes}
        for metric, (mean, half) in self.means.items():
            row[metric], row[f"{metric}_ci95"] = mean, half
        if self.reference is not None:
            ref = self.reference
            row[f"cost_vs_{ref}"], row[f"cost_vs_{ref}_ci95"] = self.paired or (math.nan, math.nan)
            if self.geometric is not None:
                g = self.geometric
                row[f"ratio_vs_{ref}"], row["ratio_low"], row["ratio_high"] = g.ratio, g.low, g.high
                row["seeds_won"] = g.won
        if self.score is not None:
            row["score"], row["score_low"], row["score_high"] = self.score.value, self.score.low, self.score.high
        return row


def _row(key: Key, members: Sequence[EpisodeResult], score: Score | None) -> RowStats:
    task, env, policy = key
    values = {m: costs_of(members, policy, env, task, m) for m, _ in SUMMARY_METRICS}
    times = values["decision_time_median_s"]
    return RowStats(key, len(members), values["control_cost"], {m: mean_ci(v.values()) for m, v in values.items()},
                    {m: sum(values[m].values()) for m in COST_METRICS},
                    1e3 * float(np.median(list(times.values()))) if times else math.nan, score)


def reduce(results: Results, version: int = SCORE_VERSION) -> Statistics:
    """The :class:`Statistics` of evaluation results (score ``version``)."""
    return Statistics(results, version)
