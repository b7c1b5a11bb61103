"""The cells of the tables: how a number, a comparison, an interval and a score read in Markdown
(every table of the reports, the zoo and the experiments formats through these)."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .stats import Geometric, RangeComparison, Score

__all__ = ["markdown_table", "fmt_pct", "fmt_num", "fmt_geometric", "fmt_paired", "format_score", "fmt_stat",
           "fmt_ranges", "fmt_tail", "fmt_worst"]


def markdown_table(header: Sequence[str], rows: Iterable[Sequence[str]]) -> str:
    """A Markdown table of string cells."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return "\n".join(lines + ["| " + " | ".join(cells) + " |" for cells in rows])


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


def format_score(score: Score | None) -> str:
    """``96.8 [91.2, 101.5]`` (the interval omitted when undefined), ``–`` for no score."""
    if score is None or not math.isfinite(score[0]):
        return "–"
    mean, lo, hi = score[:3]
    if not (math.isfinite(lo) and math.isfinite(hi)) or f"{lo:.1f}" == f"{hi:.1f}":
        return f"{mean:.1f}"
    return f"{mean:.1f} [{lo:.1f}, {hi:.1f}]"


def fmt_stat(x: float) -> str:
    """A statistic in a summary cell: four significant digits below 10, thousands separated below 1e5,
    three significant digits beyond; ``n/a`` when not finite."""
    if not math.isfinite(x):
        return "n/a"
    if x == 0 or 1e-2 <= abs(x) < 1e5:
        return f"{x:.4g}" if abs(x) < 10 else f"{x:,.1f}" if abs(x) < 1000 else f"{x:,.0f}"
    return f"{x:.3g}"


def fmt_ranges(c: RangeComparison) -> str:
    """One geometric cell per test range, separated by slashes: ``+1.2 % [-0.4, +2.9] / ...``."""
    return " / ".join(fmt_geometric(g, wins=False) for g in c.ranges)


def fmt_tail(c: RangeComparison) -> str:
    """The share of seeds in the tail: ``3 %``."""
    return f"{c.tail * 100:.0f} %"


def fmt_worst(c: RangeComparison) -> str:
    """The worst seed's ratio: ``2.14× (seed 100017)``."""
    return f"{c.worst:.2f}× (seed {c.worst_seed})"
