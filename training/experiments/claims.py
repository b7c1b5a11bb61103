"""The claims checked on an experiment's tables: the :class:`Claim` record and paired comparisons
(:func:`training.results.stats.paired_difference`) turned into claims."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from ..results.cells import fmt_paired
from ..results.stats import paired_difference, verdict

__all__ = ["Claim", "paired_claim", "combine", "multi_claim"]


@dataclass(frozen=True)
class Claim:
    """One claim checked on the tables: the paper's statement, the metric it was checked on, the
    project's number (mean and 95 % interval of the paired per-seed difference) and the verdict
    ("holds", "not significant", "differs"; "project" rows are the project's own checks)."""

    figure: str
    key: str  # stable id, e.g. "ce.expert-lowest.rg-mpc"
    claim: str
    metric: str
    value: str
    verdict: str
    seeds: int = 0


def paired_claim(figure: str, key: str, claim: str, metric: str, a: Mapping[int, float], b: Mapping[int, float],
                 expect: str) -> Claim:
    """A claim on one paired per-seed comparison of ``a`` against ``b`` (relative differences)."""
    mean, half, n = paired_difference(a, b)
    return Claim(figure, key, claim, metric, fmt_paired(mean, half), verdict(mean, half, expect), n)


def combine(verdicts: Sequence[str]) -> str:
    """One verdict of several comparisons: every interval must hold; any that differs differs."""
    if any(v == "differs" for v in verdicts):
        return "differs"
    if all(v == "holds" for v in verdicts):
        return "holds"
    return "not significant"


def multi_claim(figure: str, key: str, claim: str, metric: str,
                parts: list[tuple[str, dict[int, float], dict[int, float]]], expect: str,
                relative: bool = True) -> Claim:
    """One claim over several paired comparisons (label, a, b): every interval must hold; its seed
    count is the smallest of the comparisons'."""
    cells, verdicts, counts = [], [], []
    for label, a, b in parts:
        mean, half, n = paired_difference(a, b, relative=relative)
        cells.append(f"{label}: {fmt_paired(mean, half) if relative else f'{mean:+.3g} ± {half:.2g}'}")
        verdicts.append(verdict(mean, half, expect))
        counts.append(n)
    return Claim(figure, key, claim, metric, "; ".join(cells), combine(verdicts), min(counts, default=0))
