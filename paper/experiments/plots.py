"""The experiments' plotting helpers: a figure without pyplot state, saved as PNG and PDF, a policy's
mean curve with its 95 % interval in the policy's style, and the path figures' episode traces (the
drone's, the AGVs' and the references' positions of one episode per case, as table rows,
:func:`trace_rows`, and their plot, :func:`plot_traces`)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any, cast

import gymnasium as gym

from agents import make_policy, rollout
from evaluation.stats import mean_ci
from evaluation.sweep import SweepRow
from lawn_env import presets
from lawn_env.envs import JointEnv

from .base import QUICK_SET, Metric, values
from .rows import TraceRow

__all__ = ["STYLE", "new_figure", "save", "curve", "label_axes", "trace_rows", "plot_traces"]

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


def curve(ax: Any, rows: Sequence[SweepRow], x_key: str, y_key: Metric, policy: str, label: str | None = None,
          **kw: Any) -> None:
    """Mean and 95 % interval of ``y_key`` over the seeds at each value of the grid key ``x_key`` of one
    policy."""
    sel = [r for r in rows if r.policy == policy]
    xs = values(sel, x_key)
    if not xs:
        return
    get = y_key if callable(y_key) else (lambda r: r.metric(y_key))
    stats_ = [mean_ci([get(r) for r in sel if float(r.grid[x_key]) == x]) for x in xs]
    color, marker, ls = STYLE.get(policy, ("k", ".", "-"))
    ax.errorbar(xs, [m for m, _ in stats_], yerr=[0.0 if not math.isfinite(h) else h for _, h in stats_],
                color=kw.pop("color", color), marker=marker, ls=kw.pop("ls", ls), ms=4, capsize=3,
                label=label or policy, **kw)


def label_axes(ax: Any, title: str, xlabel: str, ylabel: str, legend_size: int = 7) -> None:
    ax.set_title(title, fontsize=9)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.legend(fontsize=legend_size)


def trace_rows(cases: Sequence[tuple[str, str, str]], quick: bool) -> list[TraceRow]:
    """Drone, AGV and reference positions of one episode (seed 0) per (label, preset, policy)."""
    rows = []
    for label, preset, policy in cases:
        cfg = presets.get(preset).override(QUICK_SET) if quick else presets.get(preset)
        env = cast(JointEnv, gym.make("lawn/Joint-v1", config=cfg).unwrapped)
        cost = rollout(env, make_policy(policy, cfg), 0).metrics["control_cost"]
        traj = env.trajectories()
        for n in range(traj["drone_position"].shape[0]):
            drone = traj["drone_position"][n]
            rows.append(TraceRow(label, preset, policy, n, cost, "drone", drone[0], drone[1]))
            for i in range(cfg.num_agvs):
                for who, arr in (("agv", traj["agv_position"]), ("reference", traj["reference_position"])):
                    rows.append(TraceRow(label, preset, policy, n, cost, f"{who}_{i}", arr[n, i, 0], arr[n, i, 1]))
    return rows


def plot_traces(rows: Sequence[TraceRow], path: Path, cases: Sequence[tuple[str, str, str]]) -> None:
    fig = new_figure(ncols=len(cases), width=3.3, height=3.6)
    for j, (label, preset, policy) in enumerate(cases):
        ax = fig.add_subplot(1, len(cases), j + 1)
        sel = [r for r in rows if r.case == label and r.policy == policy]
        k = len({r.who for r in sel if r.who.startswith("agv_")})
        for i in range(k):
            for who, ls in (("reference", "--"), ("agv", "-")):
                pts = [(r.x, r.y) for r in sel if r.who == f"{who}_{i}"]
                ax.plot(*zip(*pts, strict=True), ls, color=f"C{i}", lw=0.9 if who == "reference" else 1.3)
        drone = [(r.x, r.y) for r in sel if r.who == "drone"]
        ax.plot(*zip(*drone, strict=True), "-", color="k", lw=1.2)
        ax.plot(*drone[-1], "k^", ms=6)
        x0, x1, y0, y1 = presets.get(preset).area_m
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)
        ax.set_aspect("equal")
        ax.set_title(f"{label}, {policy}: cost {sel[0].control_cost:,.0f}", fontsize=8)
    save(fig, path)
