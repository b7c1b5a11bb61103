"""The claims checked on an experiment's tables: the :class:`Claim` record, paired comparisons
(:func:`evaluation.stats.paired_difference`) turned into claims, and the claims' results on
disk (:func:`write_claims`, :func:`read_claims`: ``OUT/claims.json``, what the reproduction page
reads) and as a table (:func:`format_claims`, :func:`tally`)."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from evaluation.cells import fmt_paired, markdown_table
from evaluation.stats import paired_difference, verdict

__all__ = ["Claim", "paired_claim", "combine", "multi_claim", "write_claims", "read_claims", "format_claims", "tally"]


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


def write_claims(claims: Sequence[Claim], out: Path) -> Path:
    """The claims' results as ``out/claims.json`` (what the reproduction page reads) and their
    table as ``out/claims.md``."""
    out = Path(out)
    (out / "claims.md").write_text(format_claims(claims) + "\n")
    path = out / "claims.json"
    path.write_text(json.dumps([dataclasses.asdict(c) for c in claims], indent=1) + "\n")
    return path


def read_claims(out: Path) -> list[Claim]:
    """The claims :func:`write_claims` wrote to ``out/claims.json``."""
    path = Path(out) / "claims.json"
    if not path.exists():
        raise FileNotFoundError(f"{path} does not exist: run `lawn figures --out {out}` first")
    return [Claim(**c) for c in json.loads(path.read_text())]


def tally(claims: Sequence[Claim]) -> str:
    """One sentence counting the verdicts of the paper's claims and of the project's own checks."""
    paper = [c for c in claims if "project's check" not in c.claim]
    own = [c for c in claims if "project's check" in c.claim]

    def count(cs: Sequence[Claim]) -> str:
        return ", ".join(f"{sum(c.verdict == v for c in cs)} {v}" for v in ("holds", "not significant", "differs"))

    return (f"Of the paper's {len(paper)} claims checked here: {count(paper)}. "
            f"Of the project's own {len(own)} checks: {count(own)}.")


def format_claims(claims: Sequence[Claim]) -> str:
    """The claims as a Markdown table."""
    marks = {"differs": "**differs**", "not significant": "*not significant*"}
    return markdown_table(["figure", "claim", "checked on", "project's number (paired mean ± 95 % interval)", "seeds",
                           "verdict"], ([c.figure, c.claim, c.metric, c.value, str(c.seeds or "–"),
                                         marks.get(c.verdict, c.verdict)] for c in claims))
