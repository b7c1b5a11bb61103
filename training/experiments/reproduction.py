"""The generated blocks of ``docs/REPRODUCTION.md`` (:func:`write_reproduction`), from the claims'
results that ``lawn figures`` wrote (``OUT/claims.json``), the build times it recorded and its
figures, and nothing else; the page's prose is the page's.

``EXPLANATIONS`` maps a claim-key prefix to why that claim does not hold here; each names the test
or command that demonstrates the mechanism. A claim that does not hold and has no explanation is
listed as "not yet explained" in the document.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import TYPE_CHECKING, Mapping, Sequence

if TYPE_CHECKING:
    from .base import Claim

__all__ = ["EXPLANATIONS", "write_reproduction"]


_SLOT_NOISE = """One slot's realized cost is dominated by that slot's fading draw and by where each
AGV happens to be on its path; its seed-to-seed spread is far larger than the episode cost's, so even 40
seeds rarely resolve a difference on it. The episode-cost rows of the same comparison are the
meaningful ones."""

_AO = """The paper's AO is no better than equal power per slot on this scenario: on the states of an
EPA-driven episode its returned J^ is above EPA's on some slots, while the reduced-problem expert's
never is (`tests/test_reduced.py::test_paper_ao_is_no_better_than_epa_per_slot_where_rg_mpc_is`).
Its power block starts from equal power and stalls, and Algorithm 2's stopping rule ends the descent
far above the optimum (the convergence rows above). With references the AGVs can follow, the
tracking part of the cost is small and these per-slot losses decide the comparison; `rg-mpc`, which
solves the same per-slot problem to the optimum, wins the same comparison (the `rg-mpc` row)."""

EXPLANATIONS = {
    "convergence.optimum": """The AO's objective never increases (the paper's argument holds with
MODEL.md §4's safeguard), but it stops on a slow descent far above the optimum: block-coordinate
descent on strongly coupled blocks, where each power or drone step can raise ψ only a little before
the next QP. The reduced-problem expert reaches the global reference at the same slots (the value
in brackets). Tested by `tests/test_reduced.py::test_rg_mpc_is_never_worse_than_the_paper_ao_on_sampled_slots`;
measured over 200 slots by `lawn gap` (the optimality-gap page, docs/experts.md).""",
    "convergence.few-iterations": """At this slot the descent is slow enough that Algorithm 2's rule
(relative decrease per iteration below 1e-2) needs more than ten iterations; see the row above for
how far from the optimum it still is.""",
    "ce.slowest-growth": """The differences in growth are a few centimetres against the MPC-based
baselines and are dominated by the one lost AGV against EPA; 40 seeds do not resolve them. The level
comparison ("lowest RMSE") is resolved.""",
    "ce.expert-lowest-slot": _SLOT_NOISE,
    "rate.rises-slot": _SLOT_NOISE,
    "rate.steeper-slot": _SLOT_NOISE,
    "ce.expert-lowest": _AO + """ Here the predictive PID and LQR, whose power and drone are optimized by
the same blocks but whose increments need no coupled descent, track better than the AO.""",
    "blocklength.beats-epa-slot": _SLOT_NOISE,
    "blocklength.beats-sf-slot": _SLOT_NOISE,
    "blocklength.beats-epa-slot.ao-mpc": _AO,  # at 40 seeds the AO's loss shows on one slot too
    "blocklength.beats-sf-slot.ao-mpc": _AO,
    "blocklength.beats-epa": _AO,
    "blocklength.beats-sf": _AO,
    "disturbance.beats-epa": _AO,
    "paths.epa-worse": _AO,
    "paths.k3-shorter": """The claim holds for the paper's AO, whose drone takes small SCA steps. `rg-mpc`
moves the drone wherever the one-slot objective is lower, however little, and nothing in the
paper's objective charges for flying (MODEL.md §4), so its path length is set by that repositioning,
several times EPA's and the AO's (`runs/figures/data/paths-k4.csv`), not by how many AGVs it
serves.""",
    "paths.epa-longer": """The claim holds for the paper's AO. `rg-mpc` moves the drone wherever the
one-slot objective is lower, however little, and nothing in the paper's objective charges for flying
(MODEL.md §4), so its drone flies several times further than EPA's while its cost is lower (the
disturbance rows).""",
}


_METHOD = ("Each comparison is paired: the same seeds (references, initial offsets, fading draws) for both sides; "
           "relative differences are per seed, then averaged, with a 95 % t-interval. *holds*: the interval lies on "
           "the claimed side of zero; *not significant*: it contains zero; *differs*: it lies on the other side. Rows "
           "marked \"project's check\" are this project's own findings, not the paper's claims.")


def _explained(claims: Sequence[Claim], explanations: Mapping[str, str]) -> list[str]:
    """Every claim that does not hold, grouped under the explanation of its key's longest prefix;
    those without one listed as not yet explained."""
    missing, groups = [], {}  # explanation text -> the claims it explains, in table order
    for c in claims:
        if c.verdict == "holds":
            continue
        prefix = next((k for k in sorted(explanations, key=len, reverse=True) if c.key.startswith(k)), None)
        if prefix is None:
            missing.append(c.key)
        else:
            groups.setdefault(explanations[prefix].strip(), []).append(c)
    lines = []
    for text, members in groups.items():
        names = "; ".join(f"{c.figure}: {c.claim} [{c.metric}] ({c.verdict})" for c in members)
        lines += [f"* *{names}.*", "", "  " + text.replace("\n", "\n  "), ""]
    if missing:
        lines += ["* **Not yet explained:** " + ", ".join(missing), ""]
    return lines


def write_reproduction(out: Path, docs: Path, explanations: Mapping[str, str] | None = None) -> Path:
    """Fill the blocks ``reproduction`` and ``reproduction-figures`` of ``docs/REPRODUCTION.md``
    from what ``lawn figures --out OUT`` left there: the claims' results (``claims.json``), the
    build times it recorded when it ran the tables' rows (``timings.json``) and the figures (copied
    to ``docs/figures/reproduction/``). Every claim that does not hold gets the explanation keyed by
    its claim key's prefix in ``explanations`` (default :data:`EXPLANATIONS`)."""
    from ..pages import replace_body
    from . import EXPERIMENTS, format_claims, read_claims, tally

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
    lines += ["", "## The paper's claims, checked", "", _METHOD, "", tally(claims), "", format_claims(claims), "",
              "## Where the results differ from the paper, and why", ""]
    lines += _explained(claims, EXPLANATIONS if explanations is None else explanations)
    figures = "\n".join(f"![{p.stem}](figures/reproduction/{p.name})" for p in sorted(out.glob("*.png")))
    source = f"lawn figures --out {out} --docs {docs}"
    text = replace_body(path.read_text(), "reproduction", "\n".join(lines), source, where=str(path))
    text = replace_body(text, "reproduction-figures", figures, source, where=str(path))  # both found: now write
    fig_dir = docs / "figures" / "reproduction"
    fig_dir.mkdir(parents=True, exist_ok=True)
    for png in sorted(out.glob("*.png")):
        shutil.copy2(png, fig_dir / png.name)
    path.write_text(text)
    return path
