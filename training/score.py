"""The normalized score of the benchmark (D4RL's convention, adapted to a cost).

Score version 2 (:data:`SCORE_VERSION`). On one task and environment, over the seeds evaluated,
with ``E_i`` the control cost of ``epa`` (the paper's equal-power baseline), ``R_i`` that of
``dv-mpc`` (the package's best expert, the delivery-value planner) and ``x_i`` the policy's, all on
seed ``i``::

    s_i   = 100 * (E_i - x_i) / mean_j (E_j - R_j)
    score = mean_i s_i = 100 * (mean E - mean x) / (mean E - mean R)

0 is EPA, 100 is ``dv-mpc``, above 100 beats it, below 0 is worse than equal power. Version 1 put
100 at ``rg-mpc``, the paper's per-slot problem solved exactly; ``dv-mpc`` plans each command as if
it arrives and beats it on the suite's tasks (docs/benchmark.md, "Score versions"), so v2 moved the
100 there. v1 stays computable: :data:`SCORE_REFERENCES` and the ``version`` argument of
:func:`score_inputs` and :func:`scores_by_policy`.

The numerator is paired (the same seed's EPA cost), the denominator is the mean reference gap over
the seeds: the per-seed gap ``E_i - R_i`` spans orders of magnitude across seeds, and EPA can cost
less than the expert on some seeds (docs/LEADERBOARD.md, the references table), so a per-seed ratio
would be dominated by a few seeds or undefined. The 95 % interval is a paired bootstrap over seeds (the triples
``(E_i, R_i, x_i)`` resampled together, so the denominator's own uncertainty is in it;
``scipy.stats.bootstrap``, percentile method, a fixed seed).

The reference costs are not constants: they are the two reference policies' realized costs on
the same seeds, task and environment, run beside the policy (``lawn evaluate`` runs both beside
the evaluated policy, ``lawn benchmark --protocol learned`` and ``--suite`` add them to every env
they run). The references' code is versioned with the package; docs/LEADERBOARD.md lists their
mean costs per task.
"""

from __future__ import annotations

import math
from typing import Iterable, Mapping

import numpy as np

from .tables import BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED

__all__ = ["SCORE_VERSION", "SCORE_REFERENCES", "SCORE_LOW", "SCORE_HIGH", "score_references", "normalized_score", "scores_by_policy", "score_inputs",
           "aggregate_score", "format_score"]

SCORE_VERSION = 2
#: The policies that define 0 and 100, per score version.
SCORE_REFERENCES: dict[int, tuple[str, str]] = {1: ("epa", "rg-mpc"), 2: ("epa", "dv-mpc")}
#: The current version's: 0 and 100.
SCORE_LOW, SCORE_HIGH = SCORE_REFERENCES[SCORE_VERSION]


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
        return 100.0 * np.mean(e - x, axis=axis) / np.mean(e - r, axis=axis)


def normalized_score(cost: Mapping[int, float], low: Mapping[int, float], high: Mapping[int, float],
                     references: tuple[str, str] = (SCORE_LOW, SCORE_HIGH)) -> tuple[float, float, float, int]:
    """Score, 95 % interval (low end, high end) and seed count of a policy's per-seed costs
    ``cost`` against the references' per-seed costs ``low`` (EPA) and ``high`` (the best expert;
    ``references`` names both in messages), over the seeds all three hold. NaN interval for fewer
    than 3 seeds; ValueError when the references do not separate (mean low cost not above mean
    high cost), where no score is defined."""
    low_name, high_name = references
    seeds = [s for s in cost if s in low and s in high]
    if not seeds:
        raise ValueError(f"no seed holds the policy's and both references' costs: run {low_name} and {high_name} on "
                         "the same seeds, task and environment")
    x = np.array([float(cost[s]) for s in seeds])
    e = np.array([float(low[s]) for s in seeds])
    r = np.array([float(high[s]) for s in seeds])
    gap = float(np.mean(e - r))
    if not gap > 0:
        raise ValueError(f"the references do not separate on these {len(seeds)} seeds: mean {low_name} cost "
                         f"{e.mean():.6g} is not above mean {high_name} cost {r.mean():.6g}")
    score = float(_score(e, r, x))
    if len(seeds) < 3:
        return score, math.nan, math.nan, len(seeds)
    from scipy import stats  # here, not at import: the episodes' processes never load scipy.stats

    res = stats.bootstrap((e, r, x), _score, paired=True, vectorized=True, n_resamples=BOOTSTRAP_RESAMPLES,
                          method="percentile", random_state=np.random.default_rng(BOOTSTRAP_SEED))
    return score, float(res.confidence_interval.low), float(res.confidence_interval.high), len(seeds)


def score_inputs(rows: Iterable[Mapping], metric: str = "control_cost", version: int = SCORE_VERSION
                 ) -> dict[tuple[str, str, str], tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Per (task, env, policy) of evaluation rows (``policy``, ``env``, ``seed``, ``metric`` and
    optionally ``task``, default ``"default"``): the per-seed costs (E, R, x) of the two references
    of score ``version`` and the policy on the seeds all three hold, aligned. Groups without both
    references or sharing no seed with them are left out."""
    low_name, high_name = score_references(version)
    costs: dict[tuple[str, str, str], dict[int, float]] = {}
    for row in rows:
        key = (str(row.get("task") or "default"), str(row["env"]), str(row["policy"]))
        costs.setdefault(key, {})[int(row["seed"])] = float(row[metric])
    out = {}
    for (task, env, policy), cost in costs.items():
        low, high = costs.get((task, env, low_name)), costs.get((task, env, high_name))
        if low is None or high is None:
            continue
        seeds = [s for s in cost if s in low and s in high]
        if seeds:
            out[(task, env, policy)] = tuple(np.array([float(c[s]) for s in seeds]) for c in (low, high, cost))
    return out


def scores_by_policy(rows: Iterable[Mapping], metric: str = "control_cost", version: int = SCORE_VERSION
                     ) -> dict[tuple[str, str, str], tuple]:
    """Scores (version ``version``) of every (task, env, policy) of evaluation rows
    (:func:`score_inputs`), against the reference rows of the same task and env. Groups without both
    references, sharing no seed with them, or whose references do not separate (EPA not costlier
    than the best expert on average) are left out: no score is defined there."""
    out = {}
    references = score_references(version)
    for key, (e, r, x) in score_inputs(rows, metric, version).items():
        seeds = range(len(x))
        try:
            out[key] = normalized_score(dict(zip(seeds, x)), dict(zip(seeds, e)), dict(zip(seeds, r)), references)
        except ValueError:  # the references do not separate
            continue
    return out


def aggregate_score(per_task: Mapping[str, tuple[np.ndarray, np.ndarray, np.ndarray]],
                    resamples: int = BOOTSTRAP_RESAMPLES) -> tuple[float, float, float, int]:
    """The headline over tasks: rliable's interquartile mean (Agarwal et al., 2021;
    ``scipy.stats.trim_mean(scores, 0.25)``) of the per-task scores, ``int(T / 4)`` tasks dropped at
    each end (the mean of the middle four of six; nothing dropped below four tasks; rliable pools the
    runs of every task, here each task is one score), with a 95 % stratified bootstrap interval
    (each task's seeds resampled on their own, its score recomputed from the resampled (E, R, x),
    the IQM taken; percentile method, a fixed seed). ``per_task``: task -> the aligned per-seed
    costs (E, R, x) of :func:`score_inputs`. Returns (IQM, low, high, number of tasks); tasks
    whose references do not separate are left out."""
    scores, draws = [], []
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    for task in sorted(per_task):
        e, r, x = (np.asarray(a, dtype=float) for a in per_task[task])
        if not float(np.mean(e - r)) > 0:
            continue
        scores.append(float(_score(e, r, x)))
        idx = rng.integers(0, e.size, size=(resamples, e.size))
        draws.append(_score(e[idx], r[idx], x[idx], axis=1))
    if not scores:
        return math.nan, math.nan, math.nan, 0
    from scipy import stats

    iqm = float(stats.trim_mean(scores, 0.25))
    boot = stats.trim_mean(np.stack(draws, axis=1), 0.25, axis=1)
    lo, hi = np.percentile(boot, [2.5, 97.5])
    return iqm, float(lo), float(hi), len(scores)


def format_score(score: tuple[float, float, float, int] | None) -> str:
    """``96.8 [91.2, 101.5]`` (the interval omitted when undefined), ``–`` for no score."""
    if score is None or not math.isfinite(score[0]):
        return "–"
    mean, lo, hi = score[:3]
    if not (math.isfinite(lo) and math.isfinite(hi)) or f"{lo:.1f}" == f"{hi:.1f}":
        return f"{mean:.1f}"
    return f"{mean:.1f} [{lo:.1f}, {hi:.1f}]"
