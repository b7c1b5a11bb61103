"""The generated blocks of ``docs/REPRODUCTION.md`` (:func:`write_reproduction`), from the claims'
results that ``lawn figures`` wrote (``OUT/claims.json``), the build times it recorded and its
figures, and nothing else; the page's prose is the page's.

``EXPLANATIONS`` maps a claim-key prefix to the page's section that says why that claim does not
hold here. A claim that does not hold and has no such section is listed as "not yet explained".
"""

from __future__ import annotations

import json
import re
import shutil
from collections.abc import Mapping, Sequence
from pathlib import Path

from ..pages import replace_body
from .claims import Claim, format_claims, read_claims, tally
from .registry import EXPERIMENTS

__all__ = ["EXPLANATIONS", "write_reproduction"]


#: Why a claim does not hold here: its key's longest prefix -> the heading of the section of
#: docs/REPRODUCTION.md that gives the reason (the page's prose; each names the test or command that
#: shows the mechanism).
_SLOT = "One slot's cost does not resolve a difference"
_AO = "The AO is no better than equal power per slot"
EXPLANATIONS = {
    "convergence.optimum": "The AO stops far above the optimum",
    "convergence.few-iterations": "The AO needs more than ten iterations at some slots",
    "ce.slowest-growth": "Differences in RMSE growth of a few centimetres",
    "ce.expert-lowest-slot": _SLOT,
    "rate.rises-slot": _SLOT,
    "rate.steeper-slot": _SLOT,
    "ce.expert-lowest": "The predictive baselines track better than the AO",
    "blocklength.beats-epa-slot": _SLOT,
    "blocklength.beats-sf-slot": _SLOT,
    "blocklength.beats-epa-slot.ao-mpc": _AO,  # at 40 seeds the AO's loss shows on one slot too
    "blocklength.beats-sf-slot.ao-mpc": _AO,
    "blocklength.beats-epa": _AO,
    "blocklength.beats-sf": _AO,
    "disturbance.beats-epa": _AO,
    "paths.epa-worse": _AO,
    "paths.k3-shorter": "The rg-mpc drone flies further",
    "paths.epa-longer": "The rg-mpc drone flies further",
}

_METHOD = ("Each comparison is paired: the same seeds (references, initial offsets, fading draws) for both sides; "
           "relative differences are per seed, then averaged, with a 95 % t-interval. *holds*: the interval lies on "
           "the claimed side of zero; *not significant*: it contains zero; *differs*: it lies on the other side. Rows "
           "marked \"project's check\" are this project's own findings, not the paper's claims.")


def heading_anchor(heading: str) -> str:
    """The anchor MyST gives a heading (``myst_heading_anchors``): lower case, punctuation dropped,
    spaces to hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def _explained(claims: Sequence[Claim], explanations: Mapping[str, str], page: str) -> list[str]:
    """Every claim that does not hold, grouped under a link to the section of ``page`` that explains
    its key's longest prefix; those without one, or whose section the page lacks, listed as not yet
    explained."""
    headings = set(re.findall(r"^#{2,3} (.+)$", page, flags=re.MULTILINE))
    missing: list[str] = []
    groups: dict[str, list[Claim]] = {}  # heading -> the claims it explains, in table order
    for c in claims:
        if c.verdict == "holds":
            continue
        prefix = next((k for k in sorted(explanations, key=len, reverse=True) if c.key.startswith(k)), None)
        if prefix is None or explanations[prefix] not in headings:
            missing.append(c.key)
        else:
            groups.setdefault(explanations[prefix], []).append(c)
    lines = []
    for heading, members in groups.items():
        names = "; ".join(f"{c.figure}: {c.claim} [{c.metric}] ({c.verdict})" for c in members)
        lines.append(f"* *{names}.* Why: [{heading}](#{heading_anchor(heading)}).")
    if missing:
        lines.append("* **Not yet explained:** " + ", ".join(missing))
    return lines


def write_reproduction(out: Path, docs: Path, explanations: Mapping[str, str] | None = None) -> Path:
    """Fill the blocks ``reproduction``, ``reproduction-misses`` and ``reproduction-figures`` of
    ``docs/REPRODUCTION.md`` from what ``lawn figures --out OUT`` left there: the claims' results (``claims.json``), the
    build times it recorded when it ran the tables' rows (``timings.json``) and the figures (copied
    to ``docs/figures/reproduction/``). Every claim that does not hold gets the explanation keyed by
    its claim key's prefix in ``explanations`` (prefix -> the page's section heading; default
    :data:`EXPLANATIONS`)."""
    out, docs = Path(out), Path(docs)
    path = docs / "REPRODUCTION.md"
    claims = read_claims(out)
    lines = []
    record = out / "timings.json"
    timings = json.loads(record.read_text()) if record.exists() else {}
    if timings:
        lines.append(f"Time to build the tables and figures from scratch (`--workers 2`, 2 cores): "
                     f"{sum(timings.values()) / 60:.1f} min (" + ", ".join(f"{k} {v:.0f} s" for k, v in timings.items())
                     + ").")
    lines += ["", "## Settings", "", "| figure | setting |", "|---|---|"]
    lines += [f"| {e.name} | {e.setting} |" for e in EXPERIMENTS.values()]
    lines += ["", "## The paper's claims, checked", "", _METHOD, "", tally(claims), "", format_claims(claims)]
    page = path.read_text()
    misses = _explained(claims, EXPLANATIONS if explanations is None else explanations, page)
    figures = "\n".join(f"![{p.stem}](figures/reproduction/{p.name})" for p in sorted(out.glob("*.png")))
    source = f"lawn figures --out {out} --docs {docs}"
    text = replace_body(page, "reproduction", "\n".join(lines), source, where=str(path))
    text = replace_body(text, "reproduction-misses", "\n".join(misses), source, where=str(path))
    text = replace_body(text, "reproduction-figures", figures, source, where=str(path))  # all found: now write
    fig_dir = docs / "figures" / "reproduction"
    fig_dir.mkdir(parents=True, exist_ok=True)
    for png in sorted(out.glob("*.png")):
        shutil.copy2(png, fig_dir / png.name)
    path.write_text(text)
    return path
