"""The normalized score of the benchmark (D4RL's convention, adapted to a cost).

Score version 1 (:data:`SCORE_VERSION`). On one task and environment, over the seeds evaluated,
with ``E_i`` the control cost of ``epa`` (the paper's equal-power baseline), ``R_i`` that of
``rg-mpc`` (the package's best expert) and ``x_i`` the policy's, all on seed ``i``::

    s_i   = 100 * (E_i - x_i) / mean_j (E_j - R_j)
    score = mean_i s_i = 100 * (mean E - mean x) / (mean E - mean R)

0 is EPA, 100 is ``rg-mpc``, above 100 beats it, below 0 is worse than equal power. The numerator
is paired (the same seed's EPA cost), the denominator is the mean reference gap over the seeds:
the per-seed gap ``E_i - R_i`` ranges from +7.7 % to +2,050 % of ``R_i`` on the 100 test seeds
of the default task, and EPA costs no more than ``rg-mpc`` on 2 to 16 of the 100 seeds of
``k3``, ``short-blocklength``, ``imperfect-csi`` and ``disturbed`` (docs/LEADERBOARD.md, the
references table), so a per-seed ratio would be dominated by a few seeds or undefined. The 95 % interval is a paired bootstrap over seeds (the triples
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
from scipy import stats

from .tables import BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED

__all__ = ["SCORE_VERSION", "SCORE_LOW", "SCORE_HIGH", "normalized_score", "scores_by_policy", "score_inputs",
           "aggregate_score", "format_score"]

SCORE_VERSION = 1
#: The policies that define 0 and 100.
SCORE_LOW, SCORE_HIGH = "epa", "rg-mpc"


def normalized_score(cost: Mapping[int, float], low: Mapping[int, float], high: Mapping[int, float]
                     ) -> tuple[float, float, float, int]:
    """Score, 95 % interval (low end, high end) and seed count of a policy's per-seed costs
    ``cost`` against the references' per-seed costs ``low`` (EPA) and ``high`` (rg-mpc), over the
    seeds all three hold. NaN interval for fewer than 3 seeds; ValueError when the references do
    not separate (mean EPA cost not above mean rg-mpc cost), where no score is defined."""
    seeds = [s for s in cost if s in low and s in high]
    if not seeds:
        raise ValueError("no seed holds the policy's and both references' costs: run epa and rg-mpc on the "
                         "same seeds, task and environment")
    x = np.array([float(cost[s]) for s in seeds])
    e = np.array([float(low[s]) for s in seeds])
    r = np.array([float(high[s]) for s in seeds])
    gap = float(np.mean(e - r))
    if not gap > 0:
        raise ValueError(f"the references do not separate on these {len(seeds)} seeds: mean {SCORE_LOW} cost "
                         f"{e.mean():.6g} is not above mean {SCORE_HIGH} cost {r.mean():.6g}")
    score = 100.0 * float(np.mean(e - x)) / gap
    if len(seeds) < 3:
        return score, math.nan, math.nan, len(seeds)

    def statistic(e_, r_, x_, axis=-1):
        return 100.0 * np.mean(e_ - x_, axis=axis) / np.mean(e_ - r_, axis=axis)

    res = stats.bootstrap((e, r, x), statistic, paired=True, vectorized=True, n_resamples=BOOTSTRAP_RESAMPLES,
                          method="percentile", random_state=np.random.default_rng(BOOTSTRAP_SEED))
    return score, float(res.confidence_interval.low), float(res.confidence_interval.high), len(seeds)


def score_inputs(rows: Iterable[Mapping], metric: str = "control_cost"
                 ) -> dict[tuple[str, str, str], tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Per (task, env, policy) of evaluation rows (``policy``, ``env``, ``seed``, ``metric`` and
    optionally ``task``, default ``"default"``): the per-seed costs (E, R, x) of the two references
    and the policy on the seeds all three hold, aligned. Groups without both references or sharing
    no seed with them are left out."""
    costs: dict[tuple[str, str, str], dict[int, float]] = {}
    for row in rows:
        key = (str(row.get("task") or "default"), str(row["env"]), str(row["policy"]))
        costs.setdefault(key, {})[int(row["seed"])] = float(row[metric])
    out = {}
    for (task, env, policy), cost in costs.items():
        low, high = costs.get((task, env, SCORE_LOW)), costs.get((task, env, SCORE_HIGH))
        if low is None or high is None:
            continue
        seeds = [s for s in cost if s in low and s in high]
        if seeds:
            out[(task, env, policy)] = tuple(np.array([float(c[s]) for s in seeds]) for c in (low, high, cost))
    return out


def scores_by_policy(rows: Iterable[Mapping], metric: str = "control_cost") -> dict[tuple[str, str, str], tuple]:
    """Scores of every (task, env, policy) of evaluation rows (:func:`score_inputs`), against the
    reference rows of the same task and env. Groups without both references, sharing no seed with
    them, or whose references do not separate (EPA not costlier than rg-mpc on average) are left
    out: no score is defined there."""
    out = {}
    for key, (e, r, x) in score_inputs(rows, metric).items():
        seeds = range(len(x))
        try:
            out[key] = normalized_score(dict(zip(seeds, x)), dict(zip(seeds, e)), dict(zip(seeds, r)))
        except ValueError:  # the references do not separate
            continue
    return out


def aggregate_score(per_task: Mapping[str, tuple[np.ndarray, np.ndarray, np.ndarray]],
                    resamples: int = BOOTSTRAP_RESAMPLES) -> tuple[float, float, float, int]:
    """The headline over tasks, rliable's convention (Agarwal et al., 2021): the interquartile mean
    of the per-task scores (``scipy.stats.trim_mean(scores, 0.25)``: the lowest and highest quarter
    of the tasks dropped, ``int(0.25 T)`` at each end) with a 95 % stratified bootstrap interval
    (each task's seeds resampled on their own, its score recomputed from the resampled (E, R, x),
    the IQM taken; percentile method, a fixed seed). ``per_task``: task -> the aligned per-seed
    costs (E, R, x) of :func:`score_inputs`. Returns (IQM, low, high, number of tasks); tasks
    whose references do not separate are left out."""
    scores, draws = [], []
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    for task in sorted(per_task):
        e, r, x = (np.asarray(a, dtype=float) for a in per_task[task])
        gap = float(np.mean(e - r))
        if not gap > 0:
            continue
        scores.append(100.0 * float(np.mean(e - x)) / gap)
        idx = rng.integers(0, e.size, size=(resamples, e.size))
        gaps = np.mean(e[idx] - r[idx], axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            draws.append(np.where(gaps > 0, 100.0 * np.mean(e[idx] - x[idx], axis=1) / gaps, np.nan))
    if not scores:
        return math.nan, math.nan, math.nan, 0
    iqm = float(stats.trim_mean(scores, 0.25))
    boot = stats.trim_mean(np.stack(draws, axis=1), 0.25, axis=1)
    boot = boot[np.isfinite(boot)]  # resamples where a task's references did not separate have no score
    lo, hi = np.percentile(boot, [2.5, 97.5]) if boot.size else (math.nan, math.nan)
    return iqm, float(lo), float(hi), len(scores)


def format_score(score: tuple[float, float, float, int] | None) -> str:
    """``96.8 [91.2, 101.5]`` (the interval omitted when undefined), ``–`` for no score."""
    if score is None or not math.isfinite(score[0]):
        return "–"
    mean, lo, hi = score[:3]
    if not (math.isfinite(lo) and math.isfinite(hi)) or f"{lo:.1f}" == f"{hi:.1f}":
        return f"{mean:.1f}"
    return f"{mean:.1f} [{lo:.1f}, {hi:.1f}]"
