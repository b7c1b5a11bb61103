"""What every experiment module shares: the :class:`Experiment` and :class:`Claim` records, sweep
specs, reading seeds out of tables, paired claims, and the plotting helpers."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

from ..results.report import fmt_paired
from ..results.stats import mean_ci, paired_difference, verdict

__all__ = [
    "Claim",
    "Experiment",
    "EXPERTS",
    "BASELINES",
    "REPORT_SLOT",
    "SEEDS",
    "QUICK_SEEDS",
    "QUICK_SET",
    "STYLE",
    "spec",
    "pick",
    "seeds",
    "cell",
    "slot_cost",
    "by_seed",
    "values",
    "paired_claim",
    "combine",
    "multi_claim",
    "new_figure",
    "save",
    "curve",
    "label_axes",
]

EXPERTS = ("rg-mpc", "ao-mpc")
BASELINES = ("epa", "pid", "lqr")
#: The paper's "selected time slot" of its rate, blocklength and CE figures.
REPORT_SLOT = 11
#: Episode seeds of every sweep behind a claim (full mode), and in ``--quick`` mode.
SEEDS = 40
QUICK_SEEDS = 2
STYLE = {
    "rg-mpc": ("C3", "o", "-"),
    "ao-mpc": ("C0", "s", "-"),
    "epa": ("C1", "^", "--"),
    "sf": ("C2", "v", "--"),
    "pid": ("C4", "D", ":"),
    "lqr": ("C5", "x", ":"),
}
QUICK_SET = {"num_slots": 30}


# ---------------------------------------------------------------------- records
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


@dataclass(frozen=True)
class Experiment:
    """One figure of MODEL.md §7 as data: its tables (sweep specs, full and ``--quick``, and
    builders of the tables that are not episode sweeps), a plot that reads only those tables, and
    the function that checks the paper's claims about it on them."""

    name: str
    setting: str  # one line for the settings table of REPRODUCTION.md
    sweeps: Callable[[bool], dict[str, dict]] = lambda quick: {}  # table name -> sweep spec
    builders: dict[str, Callable[[Path, bool], list[dict]]] = field(default_factory=dict)  # non-sweep tables
    plot: Callable[[dict[str, list[dict]], Path], None] | None = None
    claims: Callable[[dict[str, list[dict]]], list[Claim]] = lambda tables: []

    def table_names(self, quick: bool = False) -> list[str]:
        return list(self.sweeps(quick)) + list(self.builders)


# ---------------------------------------------------------------------- sweep specs
def spec(
    name: str, grid: dict, policies: Sequence[str], seeds: int, preset: str = "default", set_: dict | None = None
) -> dict:
    """A sweep spec (:func:`training.sweep.run_sweep`) on ``lawn/Joint-v1``."""
    return {
        "name": name,
        "env": "lawn/Joint-v1",
        "preset": preset,
        "set": dict(set_ or {}),
        "grid": grid,
        "policies": list(policies),
        "seeds": seeds,
    }


def pick(quick: bool, full: Any, short: Any) -> Any:
    """``short`` in ``--quick`` mode, else ``full``."""
    return short if quick else full


def seeds(quick: bool) -> int:
    """Episode seeds of a sweep behind a claim: :data:`SEEDS`, or :data:`QUICK_SEEDS` in ``--quick`` mode."""
    return QUICK_SEEDS if quick else SEEDS


# ---------------------------------------------------------------------- reading tables
def cell(row: Mapping[str, Any], key: str) -> float:
    """A numeric table cell."""
    return float(row[key])


def slot_cost(row: Mapping[str, Any], slot: int = REPORT_SLOT) -> float:
    """The realized stage cost of ``slot`` in an episode row (``stage_costs``, a JSON list)."""
    costs = json.loads(row["stage_costs"]) if isinstance(row["stage_costs"], str) else row["stage_costs"]
    return float(costs[min(slot, len(costs) - 1)])


def by_seed(rows: Sequence[Mapping], metric: str | Callable, **where: Any) -> dict[int, float]:
    """{seed: value} of the rows matching ``where`` (values compared as strings)."""
    get = metric if callable(metric) else (lambda r: cell(r, metric))
    out = {}
    for r in rows:
        if all(str(r[k]) == str(v) for k, v in where.items()):
            out[int(r["seed"])] = get(r)
    return out


def values(rows: Sequence[Mapping], key: str) -> list[float]:
    """The sorted distinct values of a numeric column."""
    return sorted({float(r[key]) for r in rows})


# ---------------------------------------------------------------------- claims
def paired_claim(figure: str, key: str, claim: str, metric: str, a: Mapping, b: Mapping, expect: str) -> Claim:
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


def multi_claim(
    figure: str,
    key: str,
    claim: str,
    metric: str,
    parts: list[tuple[str, dict, dict]],
    expect: str,
    relative: bool = True,
) -> Claim:
    """One claim over several paired comparisons (label, a, b): every interval must hold; its seed
    count is the smallest of the comparisons'."""
    cells, verdicts, counts = [], [], []
    for label, a, b in parts:
        mean, half, n = paired_difference(a, b, relative=relative)
        cells.append(f"{label}: {fmt_paired(mean, half) if relative else f'{mean:+.3g} ± {half:.2g}'}")
        verdicts.append(verdict(mean, half, expect))
        counts.append(n)
    return Claim(figure, key, claim, metric, "; ".join(cells), combine(verdicts), min(counts, default=0))


# ---------------------------------------------------------------------- plotting
def new_figure(ncols: int = 1, width: float = 5.0, height: float = 3.6) -> Any:
    """A matplotlib Figure on the Agg canvas (no pyplot state)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width * ncols, height), dpi=110)
    FigureCanvasAgg(fig)
    return fig


def save(fig: Any, path: Path) -> None:
    """``path``.png and ``path``.pdf."""
    fig.tight_layout()
    fig.savefig(path.with_suffix(".png"))
    fig.savefig(path.with_suffix(".pdf"))


def curve(
    ax: Any,
    rows: Sequence[Mapping],
    x_key: str,
    y_key: str | Callable,
    policy: str,
    label: str | None = None,
    **kw: Any,
) -> None:
    """Mean and 95 % interval of ``y_key`` over the seeds at each ``x_key`` of one policy."""
    sel = [r for r in rows if r["policy"] == policy]
    xs = values(sel, x_key)
    if not xs:
        return
    get = y_key if callable(y_key) else (lambda r: cell(r, y_key))
    stats_ = [mean_ci([get(r) for r in sel if float(r[x_key]) == x]) for x in xs]
    color, marker, ls = STYLE.get(policy, ("k", ".", "-"))
    ax.errorbar(
        xs,
        [m for m, _ in stats_],
        yerr=[0.0 if not math.isfinite(h) else h for _, h in stats_],
        color=kw.pop("color", color),
        marker=marker,
        ls=kw.pop("ls", ls),
        ms=4,
        capsize=3,
        label=label or policy,
        **kw,
    )


def label_axes(ax: Any, title: str, xlabel: str, ylabel: str, legend_size: int = 7) -> None:
    ax.set_title(title, fontsize=9)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.legend(fontsize=legend_size)
