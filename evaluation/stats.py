"""Statistics on evaluation rows: mean and 95 % t-interval, paired per-seed comparisons (relative
differences and the geometric mean of cost ratios with a bootstrap interval), the verdict of a
claim, and the normalized score with its interquartile mean over tasks.

**The normalized score** (v3, :data:`SCORE_VERSION`; docs/benchmark.md defines it and says why):
on one task and env, with ``E_i``, ``R_i`` and ``x_i`` the log costs of ``epa``, ``dv-mpc`` and the
policy on seed ``i``, ``score = 100 * (mean E - mean x) / (mean E - mean R)`` (0 is EPA, 100 the
best expert): on log cost, the score of the geometric mean, so one diverged episode of a reference
(costs 1e5 times the others') does not squash the scale; the 95 % interval is a paired bootstrap of
the triples over seeds. The references are run beside the policy on the same seeds, never stored.
Earlier versions stay computable (:data:`SCORE_REFERENCES`, :data:`SCORE_SCALES` and the
``version`` arguments): v2 on cost with 100 at ``dv-mpc-ce`` (``dv-mpc`` before its loss-aware tail),
v1 on cost with 100 at ``rg-mpc``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from .seeds import TEST_RANGES, range_of

if TYPE_CHECKING:
    from .episode import EpisodeResult, Results

__all__ = ["SUMMARY_METRICS", "Interval", "Difference", "Score",
           "mean_ci", "paired_difference", "Geometric", "paired_geometric", "verdict", "costs_of",
           "paired", "SCORE_VERSION",
           "SCORE_REFERENCES", "SCORE_SCALES", "SCORE_LOW", "SCORE_HIGH", "score_references", "score_version",
           "normalized_score", "score_inputs",
           "scores_by_policy", "aggregate_score", "TAIL_RATIO",
           "RangeComparison", "compare_ranges"]

#: Resamples of every bootstrap interval of the tables (the score's and the geometric comparison's).
BOOTSTRAP_RESAMPLES = 2000
#: The bootstraps' fixed seed: the same rows give the same interval.
BOOTSTRAP_SEED = 20261124
SCORE_VERSION = 3
#: The policies that define 0 and 100, per score version.
SCORE_REFERENCES: dict[int, tuple[str, str]] = {1: ("epa", "rg-mpc"), 2: ("epa", "dv-mpc-ce"), 3: ("epa", "dv-mpc")}
#: What each version averages: the costs ("cost") or their logarithms ("log cost").
SCORE_SCALES: dict[int, str] = {1: "cost", 2: "cost", 3: "log cost"}
#: The current version's: 0 and 100.
SCORE_LOW, SCORE_HIGH = SCORE_REFERENCES[SCORE_VERSION]
#: The aligned per-seed costs (E, R, x) of the two references and a policy (:func:`score_inputs`).
Costs = tuple[np.ndarray, np.ndarray, np.ndarray]
#: A seed is in the tail when it costs over this many times the reference.
TAIL_RATIO = 1.5
#: Metrics summarized with a mean and a 95 % interval (name, label).
SUMMARY_METRICS = (
    ("control_cost", "control cost"),
    ("transient_cost", "transient cost"),
    ("sustained_cost", "sustained cost"),
    ("rmse_m", "RMSE (m)"),
    ("outage_rate", "outage rate"),
    ("diverged", "diverged"),
    ("decision_time_median_s", "decision time (s)"),
)


class Interval(NamedTuple):
    """A mean and its 95 % interval's half-width (NaN where undefined)."""

    mean: float
    half: float


class Difference(NamedTuple):
    """A paired difference: its mean, the 95 % half-width and the number of pairs."""

    mean: float
    half: float
    pairs: int


class Score(NamedTuple):
    """A normalized score (or its IQM over tasks), the ends of its 95 % bootstrap interval (NaN for
    fewer than 3 seeds) and the number of seeds (or tasks) it is over."""

    value: float
    low: float
    high: float
    n: int


def mean_ci(values: Iterable[float]) -> Interval:
    """Mean and 95 % t-interval half-width (NaN for fewer than two values)."""
    x = np.asarray([float(v) for v in values], dtype=float)
    if x.size == 0:
        return Interval(math.nan, math.nan)
    if x.size < 2:
        return Interval(float(x.mean()), math.nan)
    from scipy import stats  # here, not at import: the episodes' processes never load scipy.stats

    return Interval(float(x.mean()), float(stats.t.ppf(0.975, x.size - 1) * x.std(ddof=1) / math.sqrt(x.size)))


def paired_difference(a: Mapping[int, float], b: Mapping[int, float], relative: bool = True) -> Difference:
    """Mean, 95 % t-interval half-width and count of the per-key difference ``a[k] - b[k]`` over the
    keys (seeds) both hold; ``relative`` divides each difference by ``b[k]`` (a paired comparison)."""
    keys = [k for k in a if k in b]
    diffs = [(float(a[k]) - float(b[k])) / (abs(float(b[k])) if relative else 1.0) for k in keys]
    mean, half = mean_ci(diffs)
    return Difference(mean, half, len(diffs))


@dataclass(frozen=True)
class Geometric:
    """A paired comparison on the log scale: ``ratio`` = exp(mean_i log(a_i / b_i)), the geometric
    mean of the per-seed cost ratios, with its 95 % bootstrap interval (``low``, ``high``), the
    number of ``seeds`` and the share of them ``a`` ``won`` (a_i < b_i; a tie counts half)."""

    ratio: float
    low: float
    high: float
    seeds: int
    won: float

    @property
    def change(self) -> float:
        """The relative change ratio - 1 (-0.1 is 10 % below the reference)."""
        return self.ratio - 1.0

    @property
    def excludes_zero(self) -> bool:
        """The 95 % interval lies on one side of no change."""
        return bool(self.high < 1.0 or self.low > 1.0)


def paired_geometric(a: Mapping[int, float], b: Mapping[int, float], resamples: int = BOOTSTRAP_RESAMPLES) -> Geometric:
    """The geometric mean of the per-key (seed) cost ratios ``a[k] / b[k]`` over the keys both hold,
    its 95 % percentile bootstrap interval (``scipy.stats.bootstrap`` on the log-ratios, a fixed
    seed; NaN for fewer than 3 seeds) and the share of seeds ``a`` won. On heavy-tailed costs the
    mean of relative differences follows the few seeds where one cost is many times the other; the
    mean log-ratio weighs a halving and a doubling alike (docs/benchmark.md). Costs must be > 0."""
    keys = [k for k in a if k in b]
    if not keys:
        raise ValueError("paired_geometric: the two cost maps share no seed")
    x = np.array([float(a[k]) for k in keys])
    y = np.array([float(b[k]) for k in keys])
    bad = [k for k, u, v in zip(keys, x, y, strict=True) if not (u > 0 and v > 0 and np.isfinite(u) and np.isfinite(v))]
    if bad:
        raise ValueError(f"paired_geometric: every cost must be > 0 and finite; seed {bad[0]!r} has {a[bad[0]]!r} "
                         f"against {b[bad[0]]!r}")
    logs = np.log(x) - np.log(y)
    won = float(np.mean((logs < 0) + 0.5 * (logs == 0)))
    mean = float(logs.mean())
    if logs.size < 3:
        lo = hi = math.nan
    elif np.ptp(logs) == 0:  # every seed the same ratio: the bootstrap distribution is that point
        lo = hi = mean
    else:
        from scipy import stats

        res = stats.bootstrap((logs,), np.mean, vectorized=True, n_resamples=resamples, method="percentile",
                              random_state=np.random.default_rng(BOOTSTRAP_SEED))
        lo, hi = float(res.confidence_interval.low), float(res.confidence_interval.high)
    return Geometric(math.exp(mean), math.exp(lo), math.exp(hi), int(logs.size), won)


def verdict(mean: float, half: float, expect: str, tie_tolerance: float = 0.01) -> str:
    """"holds" when the 95 % interval lies on the ``expect``ed side of zero ("negative" or
    "positive"), "differs" when it lies on the other side, else "not significant". With
    ``expect="tie"`` it holds when the whole interval lies within ``±tie_tolerance`` and differs when
    it lies entirely outside."""
    if expect not in ("negative", "positive", "tie"):
        raise ValueError(f"expect={expect!r}: must be 'negative', 'positive' or 'tie'")
    if not (math.isfinite(mean) and math.isfinite(half)):
        return "n/a"
    lo, hi = mean - half, mean + half
    if expect == "tie":
        if -tie_tolerance <= lo and hi <= tie_tolerance:
            return "holds"
        return "differs" if lo > tie_tolerance or hi < -tie_tolerance else "not significant"
    if expect == "positive":
        lo, hi = -hi, -lo
    if hi < 0:
        return "holds"
    if lo > 0:
        return "differs"
    return "not significant"


def costs_of(rows: Results, policy: str, env: str | None = None, task: str | None = None,
             metric: str = "control_cost") -> dict[int, float]:
    """``metric`` (default: the control cost) per seed of ``policy`` (on ``env`` and ``task``, when
    given) in evaluation results that record it."""
    return {r.seed: v for r in rows if r.policy == policy and (env is None or r.env == env)
            and (task is None or (r.task or "default") == task) and (v := r.value(metric)) is not None}


def paired(rows: Results, policy: str, reference: str, env: str, task: str | None = None) -> Interval:
    """Mean per-seed relative difference of ``policy``'s cost against ``reference``'s (on ``env``, and
    ``task`` when given) and its 95 % half-width."""
    mean, half, _ = paired_difference(costs_of(rows, policy, env, task), costs_of(rows, reference, env, task))
    return Interval(mean, half)


def score_references(version: int = SCORE_VERSION) -> tuple[str, str]:
    """The policies at 0 and 100 of score ``version``; ValueError naming the versions otherwise."""
    try:
        return SCORE_REFERENCES[version]
    except (KeyError, TypeError):
        raise ValueError(f"score version={version!r}; valid: {', '.join(map(str, SCORE_REFERENCES))}") from None


def _score(e: np.ndarray, r: np.ndarray, x: np.ndarray, axis: int = -1) -> np.ndarray:
    """The score's formula, 100 (mean E - mean x) / (mean E - mean R), along ``axis``. The callers
    refuse a sample whose references do not separate; a bootstrap resample that does not is kept as
    it comes out (both intervals, the task's and the aggregate's, treat it alike)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        score: np.ndarray = 100.0 * np.mean(e - x, axis=axis) / np.mean(e - r, axis=axis)
        return score


def _scaled(costs: np.ndarray, version: int) -> np.ndarray:
    """The values score ``version`` averages: the costs, or their logarithms (positive costs only)."""
    if SCORE_SCALES[score_version(version)] == "cost":
        return costs
    if not np.all(costs > 0):
        raise ValueError(f"score v{version} averages log costs: every cost must be > 0 (got {costs.min():.6g})")
    scaled: np.ndarray = np.log(costs)
    return scaled


def score_version(version: int) -> int:
    """``version`` if it is one; ValueError naming the versions otherwise."""
    score_references(version)
    return version


def normalized_score(cost: Mapping[int, float], low: Mapping[int, float], high: Mapping[int, float],
                     references: tuple[str, str] | None = None, version: int = SCORE_VERSION) -> Score:
    """Score ``version``, its 95 % interval (low end, high end) and seed count of a policy's per-seed
    costs ``cost`` against the references' ``low`` (EPA) and ``high`` (the best expert; ``references``
    names both in messages, default the version's), over the seeds all three hold. NaN interval for
    fewer than 3 seeds; ValueError when the references do not separate (mean low cost, or log cost,
    not above the high one's): no score is defined."""
    low_name, high_name = score_references(version) if references is None else references
    seeds = [s for s in cost if s in low and s in high]
    if not seeds:
        raise ValueError(f"no seed holds the policy's and both references' costs: run {low_name} and {high_name} on "
                         "the same seeds, task and environment")
    x = _scaled(np.array([float(cost[s]) for s in seeds]), version)
    e = _scaled(np.array([float(low[s]) for s in seeds]), version)
    r = _scaled(np.array([float(high[s]) for s in seeds]), version)
    gap = float(np.mean(e - r))
    if not gap > 0:
        scale = SCORE_SCALES[version]
        raise ValueError(f"the references do not separate on these {len(seeds)} seeds: mean {low_name} {scale} "
                         f"{e.mean():.6g} is not above mean {high_name} {scale} {r.mean():.6g}")
    score = float(_score(e, r, x))
    if len(seeds) < 3:
        return Score(score, math.nan, math.nan, len(seeds))
    from scipy import stats  # here, not at import: the episodes' processes never load scipy.stats

    res = stats.bootstrap((e, r, x), _score, paired=True, vectorized=True, n_resamples=BOOTSTRAP_RESAMPLES,
                          method="percentile", random_state=np.random.default_rng(BOOTSTRAP_SEED))
    return Score(score, float(res.confidence_interval.low), float(res.confidence_interval.high), len(seeds))


def score_inputs(rows: Iterable[EpisodeResult], metric: str = "control_cost", version: int = SCORE_VERSION
                 ) -> dict[tuple[str, str, str], Costs]:
    """Per (task, env, policy) of evaluation results (task None read as ``"default"``): the per-seed
    costs (E, R, x) of the two references of score ``version`` and the policy on the seeds all three
    hold, aligned. Groups without both references or sharing no seed with them are left out."""
    low_name, high_name = score_references(version)
    costs: dict[tuple[str, str, str], dict[int, float]] = {}
    for row in rows:
        value = row.value(metric)
        if value is not None:
            costs.setdefault((row.task or "default", row.env, row.policy), {})[row.seed] = value
    out = {}
    for (task, env, policy), cost in costs.items():
        low, high = costs.get((task, env, low_name)), costs.get((task, env, high_name))
        if low is None or high is None:
            continue
        seeds = [s for s in cost if s in low and s in high]
        if seeds:
            e, r, x = (np.array([float(c[s]) for s in seeds]) for c in (low, high, cost))
            out[(task, env, policy)] = (e, r, x)
    return out


def scores_by_policy(rows: Iterable[EpisodeResult], metric: str = "control_cost", version: int = SCORE_VERSION
                     ) -> dict[tuple[str, str, str], Score]:
    """Scores (version ``version``) of every (task, env, policy) of evaluation rows
    (:func:`score_inputs`), against the reference rows of the same task and env. Groups without both
    references, sharing no seed with them, or whose references do not separate (EPA not costlier
    than the best expert on average) are left out: no score is defined there."""
    references = score_references(version)
    return {key: normalized_score(dict(enumerate(x)), dict(enumerate(e)), dict(enumerate(r)), references, version)
            for key, (e, r, x) in score_inputs(rows, metric, version).items()
            if float(np.mean(_scaled(e, version) - _scaled(r, version))) > 0}


def aggregate_score(per_task: Mapping[str, Costs], resamples: int = BOOTSTRAP_RESAMPLES,
                    version: int = SCORE_VERSION) -> Score:
    """The headline over tasks: rliable's interquartile mean (Agarwal et al., 2021) of the per-task
    scores (``scipy.stats.trim_mean(scores, 0.25)``: the middle four of six), with a 95 % stratified
    bootstrap interval (each task's seeds resampled on their own, its score recomputed, the IQM
    taken; percentile method, a fixed seed). ``per_task``: task -> the costs (E, R, x) of
    :func:`score_inputs`. Returns (IQM, low, high, number of tasks); tasks whose references do not
    separate are left out."""
    scores, draws = [], []
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    for task in sorted(per_task):
        e, r, x = (_scaled(np.asarray(a, dtype=float), version) for a in per_task[task])
        if not float(np.mean(e - r)) > 0:
            continue
        scores.append(float(_score(e, r, x)))
        idx = rng.integers(0, e.size, size=(resamples, e.size))
        draws.append(_score(e[idx], r[idx], x[idx], axis=1))
    if not scores:
        return Score(math.nan, math.nan, math.nan, 0)
    from scipy import stats

    iqm = float(stats.trim_mean(scores, 0.25))
    boot = stats.trim_mean(np.stack(draws, axis=1), 0.25, axis=1)
    lo, hi = np.percentile(boot, [2.5, 97.5])
    return Score(iqm, float(lo), float(hi), len(scores))


@dataclass(frozen=True)
class RangeComparison:
    """Per-seed costs against a reference on the test ranges: the geometric comparison on each range,
    the share of all seeds over :data:`TAIL_RATIO` times the reference (a network that loses an AGV on
    one seed in twenty is not hidden by a geometric mean), and the worst seed and its ratio."""

    ranges: tuple[Geometric, ...]
    tail: float
    worst: float
    worst_seed: int

    def below(self, bound: float) -> bool:
        """Every range's upper interval bound on the ratio is at most ``bound`` (1.05: +5 %)."""
        return all(math.isfinite(g.high) and g.high <= bound for g in self.ranges)


def compare_ranges(costs: Mapping[int, float], reference: Mapping[int, float]) -> RangeComparison:
    """:class:`RangeComparison` of ``costs`` against ``reference`` on the seeds both hold."""
    seeds = sorted(s for s in costs if s in reference)
    if not seeds:
        raise ValueError("compare_ranges: the costs and the reference share no seed")
    groups = [[s for s in seeds if range_of(s) == i] for i in range(len(TEST_RANGES))]
    ranges = tuple(paired_geometric({s: costs[s] for s in g}, {s: reference[s] for s in g}) for g in groups if g)
    ratio = np.array([costs[s] / reference[s] for s in seeds])
    worst = int(np.argmax(ratio))
    return RangeComparison(ranges, float(np.mean(ratio > TAIL_RATIO)), float(ratio[worst]), seeds[worst])
