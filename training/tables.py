"""The table layer of every report: CSV rows written and read one way (:func:`write_csv`,
:func:`read_csv`, :func:`parse_bool`) and the summary statistics (mean and 95 % t-interval
half-width, the paired per-seed difference, the verdict of a claim)."""

from __future__ import annotations

import csv
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Mapping

import numpy as np

__all__ = ["mean_ci", "paired_difference", "Geometric", "paired_geometric", "verdict", "write_csv", "read_csv",
           "parse_bool", "fmt_pct", "fmt_num", "fmt_paired", "fmt_geometric"]

#: Resamples of every bootstrap interval of the tables (the score's and the geometric comparison's).
BOOTSTRAP_RESAMPLES = 2000
#: The bootstraps' fixed seed: the same rows give the same interval.
BOOTSTRAP_SEED = 20261124


def write_csv(rows: list[dict], path: Path | str, atomic: bool = False) -> Path:
    """Rows as CSV with the union of their keys as columns (first-seen order). ``atomic`` writes a
    temporary file, syncs it and renames it over ``path``, so a reader never sees half a table."""
    path = Path(path)
    fields: list[str] = []
    for row in rows:
        fields += [k for k in row if k not in fields]
    target = path.with_suffix(path.suffix + ".tmp") if atomic else path
    with target.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=fields)
        writer.writeheader()
        writer.writerows(rows)
        if atomic:
            fh.flush()
            os.fsync(fh.fileno())
    if atomic:
        os.replace(target, path)
    return path


def read_csv(path: Path | str) -> list[dict[str, str]]:
    """The rows of a CSV file as dicts of strings (an empty list when the file does not exist)."""
    path = Path(path)
    if not path.exists():
        return []
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


def parse_bool(value: object) -> bool:
    """A boolean table cell: a bool, or ``true``/``false``/``1``/``0`` in any case."""
    if isinstance(value, bool):
        return value
    text = str(value).strip().lower()
    if text in ("true", "1"):
        return True
    if text in ("false", "0"):
        return False
    raise ValueError(f"not a boolean table value: {value!r}")


def mean_ci(values: Iterable[float]) -> tuple[float, float]:
    """Mean and 95 % t-interval half-width (NaN for fewer than two values)."""
    x = np.asarray([float(v) for v in values], dtype=float)
    if x.size == 0:
        return math.nan, math.nan
    if x.size < 2:
        return float(x.mean()), math.nan
    from scipy import stats  # here, not at import: the episodes' processes never load scipy.stats

    return float(x.mean()), float(stats.t.ppf(0.975, x.size - 1) * x.std(ddof=1) / math.sqrt(x.size))


def paired_difference(a: Mapping, b: Mapping, relative: bool = True) -> tuple[float, float, int]:
    """Mean, 95 % t-interval half-width and count of the per-key difference ``a[k] - b[k]`` over the
    keys (seeds) both hold; ``relative`` divides each difference by ``b[k]`` (a paired comparison)."""
    keys = [k for k in a if k in b]
    diffs = [(float(a[k]) - float(b[k])) / (abs(float(b[k])) if relative else 1.0) for k in keys]
    mean, half = mean_ci(diffs)
    return mean, half, len(diffs)


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


def paired_geometric(a: Mapping, b: Mapping, resamples: int = BOOTSTRAP_RESAMPLES) -> Geometric:
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
    bad = [k for k, u, v in zip(keys, x, y) if not (u > 0 and v > 0 and np.isfinite(u) and np.isfinite(v))]
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


def fmt_pct(x: float, sign: bool = True) -> str:
    """A fraction as a percentage: ``+3.8 %`` (``3.8 %`` without the sign); ``n/a`` when not finite."""
    if not math.isfinite(x):
        return "n/a"
    return f"{x * 100:+.1f} %" if sign else f"{x * 100:.1f} %"


def fmt_num(x: float) -> str:
    """A cost: thousands separated below 1e5, three significant digits above; ``n/a`` when not finite."""
    if not math.isfinite(x):
        return "n/a"
    return f"{x:,.0f}" if abs(x) < 1e5 else f"{x:.3g}"


def fmt_geometric(g: Geometric | None, wins: bool = True) -> str:
    """A geometric comparison: ``-17.5 % [-25.0, -9.1] (wins 61 %)``; ``n/a`` when undefined."""
    if g is None or not math.isfinite(g.ratio):
        return "n/a"
    text = fmt_pct(g.change)
    if math.isfinite(g.low) and math.isfinite(g.high):
        text += f" [{(g.low - 1) * 100:+.1f}, {(g.high - 1) * 100:+.1f}]"
    return text + (f" (wins {g.won * 100:.0f} %)" if wins else "")


def fmt_paired(mean: float, half: float) -> str:
    """A paired relative difference with its 95 % half-width: ``+3.8 % ± 4.7 %``."""
    if not math.isfinite(mean):
        return "n/a"
    return fmt_pct(mean) + ("" if not math.isfinite(half) else f" ± {fmt_pct(half, sign=False)}")
