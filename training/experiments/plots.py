"""The experiments' plotting helpers: a figure without pyplot state, saved as PNG and PDF, and a
policy's mean curve with its 95 % interval in the policy's style."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from ..results.stats import mean_ci
from .base import values

__all__ = ["STYLE", "new_figure", "save", "curve", "label_axes"]

#: Colour, marker and line style of each policy in every figure.
STYLE = {"rg-mpc": ("C3", "o", "-"), "ao-mpc": ("C0", "s", "-"), "epa": ("C1", "^", "--"), "sf": ("C2", "v", "--"),
         "pid": ("C4", "D", ":"), "lqr": ("C5", "x", ":")}


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


def curve(ax: Any, rows: Sequence[Mapping[str, Any]], x_key: str, y_key: str | Callable[..., Any], policy: str,
          label: str | None = None,
          **kw: Any) -> None:
    """Mean and 95 % interval of ``y_key`` over the seeds at each ``x_key`` of one policy."""
    sel = [r for r in rows if r["policy"] == policy]
    xs = values(sel, x_key)
    if not xs:
        return
    get = y_key if callable(y_key) else (lambda r: float(r[y_key]))
    stats_ = [mean_ci([get(r) for r in sel if float(r[x_key]) == x]) for x in xs]
    color, marker, ls = STYLE.get(policy, ("k", ".", "-"))
    ax.errorbar(xs, [m for m, _ in stats_], yerr=[0.0 if not math.isfinite(h) else h for _, h in stats_],
                color=kw.pop("color", color), marker=marker, ls=kw.pop("ls", ls), ms=4, capsize=3,
                label=label or policy, **kw)


def label_axes(ax: Any, title: str, xlabel: str, ylabel: str, legend_size: int = 7) -> None:
    ax.set_title(title, fontsize=9)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.legend(fontsize=legend_size)
