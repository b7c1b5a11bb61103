"""Summary statistics shared by the reports: mean and 95 % t-interval half-width."""

from __future__ import annotations

import math
from typing import Iterable

import numpy as np
from scipy import stats

__all__ = ["mean_ci"]


def mean_ci(values: Iterable[float]) -> tuple[float, float]:
    """Mean and 95 % t-interval half-width (NaN for fewer than two values)."""
    x = np.asarray([float(v) for v in values], dtype=float)
    if x.size == 0:
        return math.nan, math.nan
    if x.size < 2:
        return float(x.mean()), math.nan
    return float(x.mean()), float(stats.t.ppf(0.975, x.size - 1) * x.std(ddof=1) / math.sqrt(x.size))
