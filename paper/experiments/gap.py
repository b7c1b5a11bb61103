"""``lawn gap``: per-slot optimality gaps of planners against the global reference.

A driver policy runs seeded episodes; every planner under test plans at every slot (so planners
that remember their previous slot see the trajectory they would be deployed on), and at every
``every``-th slot the global reference (``global-mpc``) solves the same snapshot. The gap of a
planner at a slot is ``(J^_planner - J^_global) / J^_global``, both J^ evaluated exactly (the QPs
re-solved at each returned (p, q)). Slightly negative gaps mean the planner beat the reference
within its grid resolution.

Also the convergence figure: the AO's objective after every block of every iteration at chosen
slots, against the global reference's value.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, cast

import gymnasium as gym
import numpy as np

from agents import Step, make_policy, rollout
from agents.ao import AOSettings, AOSolver
from agents.policies import PlannerPolicy
from evaluation.cells import markdown_table
from evaluation.episode import DEFAULT_PLAY, Play, write_rows
from evaluation.pool import pool_map
from lawn_env import ScenarioConfig, Snapshot

from .rows import ConvergenceRow, GapRow, GapSummary

__all__ = ["CONVERGENCE_SLOTS", "gap_episode", "run_gap", "summarize_gaps", "global_power_shares", "format_gap_table",
           "convergence", "format_convergence", "plot_gaps", "plot_convergence", "write_gap_outputs"]


def gap_episode(policies: Sequence[str], driver: str, config: ScenarioConfig, seed: int, every: int,
                global_settings: Mapping[str, Any] | None = None) -> list[GapRow]:
    """The rows of one episode: every planner at every ``every``-th slot against the reference."""
    env = gym.make("lawn/Joint-v1", config=config).unwrapped
    drive = make_policy(driver, config)
    planners = {name: _planner(name, config) for name in policies}
    reference = _planner("global-mpc", config, **dict(global_settings or {}))
    for policy in (reference, *planners.values()):
        policy.reset(seed)
    rows: list[GapRow] = []

    def on_step(step: Step) -> None:  # the planners and the reference plan the state the driver acted in
        snap, slot = _snapshot(step), step.slot
        results = {}
        for name, policy in planners.items():
            start = time.perf_counter()
            plan = policy.plan(snap)
            results[name] = (plan, time.perf_counter() - start)
        if slot % every == 0:
            glob = reference.plan(snap)
            budget = config.power_budget_w
            for name, (plan, seconds) in results.items():
                rows.append(GapRow(seed, slot, name, plan.objective, glob.objective,
                                   (plan.objective - glob.objective) / glob.objective, seconds, glob.solve_time_s,
                                   float(plan.power_w.min() / budget), float(glob.power_w.min() / budget),
                                   tuple(plan.power_w.round(6).tolist()), tuple(glob.power_w.round(6).tolist())))

    rollout(env, drive, seed, on_step=on_step, snapshots=True)
    return rows


def _planner(name: str, config: ScenarioConfig, **settings: Any) -> PlannerPolicy:
    """A policy that plans from the full state (the experts, ``global-mpc``)."""
    return cast(PlannerPolicy, make_policy(name, config, **settings))


def _snapshot(step: Step) -> Snapshot:
    """The state a step's action was chosen in (``rollout(..., snapshots=True)`` records it)."""
    return cast(Snapshot, step.snapshot)


def _gap_task(task: tuple[Any, ...]) -> list[GapRow]:
    return gap_episode(*task)


def run_gap(policies: Sequence[str], driver: str, config: ScenarioConfig, seeds: Sequence[int], every: int,
            play: Play = DEFAULT_PLAY, global_settings: Mapping[str, Any] | None = None) -> list[GapRow]:
    """:func:`gap_episode` of every seed (``play``'s workers and progress bar), its rows in seed order."""

    tasks = [(tuple(policies), driver, config, s, every, dict(global_settings or {})) for s in seeds]
    rows: list[GapRow] = []
    for episode_rows in pool_map(_gap_task, tasks, play.workers, play.progress, desc="gap"):
        rows.extend(episode_rows)
    return rows


def summarize_gaps(rows: Sequence[GapRow], tolerance: float = 1e-6) -> list[GapSummary]:
    """Per planner: gap median / p90 / max, median decision time, and on how many slots it is
    worse than each other planner by more than ``tolerance`` (relative)."""
    names = list(dict.fromkeys(r.policy for r in rows))
    by_slot: dict[tuple[int, int], dict[str, float]] = {}
    for r in rows:
        by_slot.setdefault((r.seed, r.slot), {})[r.policy] = r.objective
    out = []
    for name in names:
        gaps = np.array([r.gap for r in rows if r.policy == name])
        times = np.array([r.decision_time_s for r in rows if r.policy == name])
        shares = np.array([r.min_power_share for r in rows if r.policy == name])
        worse = {other: sum(1 for objs in by_slot.values() if objs[name] > objs[other] * (1 + tolerance))
                 for other in names if other != name}
        out.append(GapSummary(name, int(gaps.size), float(np.median(gaps)), float(np.percentile(gaps, 90)),
                              float(gaps.max()), float(np.median(times)), int((shares < 0.05).sum()), worse))
    return out


def global_power_shares(rows: Sequence[GapRow]) -> int:
    """On how many compared slots the global reference gives some link less than 5 % of P_max."""
    seen = {(r.seed, r.slot): r.global_min_power_share for r in rows}
    return int(sum(1 for v in seen.values() if v < 0.05))


def format_gap_table(summary: Sequence[GapSummary]) -> str:
    """:func:`summarize_gaps`' rows as a Markdown table."""
    others = list(dict.fromkeys(k for e in summary for k in e.worse_than))
    header = ["planner", "slots", "gap median", "gap p90", "gap max", "decision time (ms)", "a link < 5 % power"]
    table = [[e.policy, str(e.slots), f"{e.gap_median * 100:.3f} %", f"{e.gap_p90 * 100:.3f} %",
              f"{e.gap_max * 100:.2f} %", f"{e.decision_time_median_s * 1e3:.2f}",
              f"{e.slots_with_a_link_below_5pct_power}", *(str(e.worse_than.get(k, "–")) for k in others)]
             for e in summary]
    return markdown_table([*header, *(f"worse than {k}" for k in others)], table)


def plot_gaps(rows: Sequence[GapRow], path: Path) -> None:
    """CDF of the gap per planner and the gap along the slots of the first episode."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 4), dpi=110)
    FigureCanvasAgg(fig)
    ax1, ax2 = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2)
    names = list(dict.fromkeys(r.policy for r in rows))
    first_seed = rows[0].seed
    for i, name in enumerate(names):
        gaps = np.sort([max(r.gap, 1e-7) for r in rows if r.policy == name])
        ax1.step(gaps * 100, np.arange(1, gaps.size + 1) / gaps.size, where="post", label=name, color=f"C{i}")
        ep = [(r.slot, max(r.gap, 1e-7) * 100) for r in rows if r.policy == name and r.seed == first_seed]
        ax2.semilogy([s for s, _ in ep], [g for _, g in ep], "o-", ms=3, label=name, color=f"C{i}")
    ax1.set_xscale("log")
    ax1.set_xlabel("gap to the global reference (%, floored at 1e-5 %)")
    ax1.set_ylabel("fraction of slots")
    ax1.set_title("per-slot optimality gap, all episodes", fontsize=10)
    ax1.legend()
    ax2.set_xlabel("slot")
    ax2.set_ylabel("gap (%)")
    ax2.set_title(f"along episode seed {first_seed}", fontsize=10)
    fig.tight_layout()
    fig.savefig(path)


#: The slots of the convergence figure (``lawn gap --convergence-slots`` and ``lawn figures``): early
#: transients and later regimes of the default episode.
CONVERGENCE_SLOTS = (11, 19, 28, 41)


def convergence(config: ScenarioConfig, slots: Sequence[int], seed: int = 0, driver: str = "ao-mpc",
                iterations: int = 20, global_settings: Mapping[str, Any] | None = None) -> list[ConvergenceRow]:
    """The paper's AO run for ``iterations`` (no early stop) at each of ``slots`` of a driver
    episode; rows per (slot, iteration, block) with J^, plus the global and rg-mpc values."""
    env = gym.make("lawn/Joint-v1", config=config).unwrapped
    drive = make_policy(driver, config)
    reference = _planner("global-mpc", config, **dict(global_settings or {}))
    fast = _planner("rg-mpc", config)
    ao = AOSolver(config, AOSettings(max_iterations=iterations, tolerance=0.0))
    for p in (reference, fast):
        p.reset(seed)
    wanted, last = set(slots), max(slots)
    rows: list[ConvergenceRow] = []

    def on_step(step: Step) -> bool:
        snap, slot = _snapshot(step), step.slot
        fast_value = fast.plan(snap).objective  # rg-mpc plans every slot, as deployed
        if slot in wanted:
            glob = reference.plan(snap).objective
            trace = ao.solve(snap).objective_trace
            for it, row in enumerate(trace, start=1):
                for b, block in enumerate(("control", "power", "drone")):
                    rows.append(ConvergenceRow(slot, it, block, row[b], glob, fast_value))
        return slot >= last

    rollout(env, drive, seed, on_step=on_step, snapshots=True)
    return rows


def plot_convergence(rows: Sequence[ConvergenceRow], path: Path) -> None:
    """Top: J^ after every block of every AO iteration with the global reference's and rg-mpc's
    values as lines. Bottom: the same as excess over the global reference, log scale."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    blocks = ("control", "power", "drone")
    slots = list(dict.fromkeys(r.slot for r in rows))
    fig = Figure(figsize=(3.3 * len(slots), 6.2), dpi=110)
    FigureCanvasAgg(fig)
    for i, slot in enumerate(slots):
        sel = [r for r in rows if r.slot == slot]
        glob, fast = sel[0].global_objective, sel[0].rg_mpc_objective
        x = np.array([r.iteration - 1 + (blocks.index(r.block) + 1) / 3 for r in sel])
        y = np.array([r.objective for r in sel])
        ends = np.arange(2, len(sel), 3)  # after the drone block: the end of each iteration
        top = fig.add_subplot(2, len(slots), i + 1)
        top.plot(x, y, "-", color="C0", lw=1.2, label="paper's AO (every block)")
        top.plot(x[ends], y[ends], "o", color="C0", ms=3)
        top.axhline(glob, color="k", ls="--", lw=1, label="global reference")
        top.axhline(fast, color="C3", ls=":", lw=1.5, label="rg-mpc")
        top.set_ylim(glob - 0.05 * (y[2] - glob) - 1e-9 * glob, y[2] + 0.5 * (y[2] - glob) + 1e-9 * glob)
        top.set_title(f"slot n = {slot}", fontsize=9)
        bottom = fig.add_subplot(2, len(slots), len(slots) + i + 1)
        bottom.semilogy(x, np.maximum(y / glob - 1, 1e-6) * 100, "-", color="C0", lw=1.2)
        bottom.semilogy(x[ends], np.maximum(y[ends] / glob - 1, 1e-6) * 100, "o", color="C0", ms=3)
        bottom.axhline(max(fast / glob - 1, 1e-6) * 100, color="C3", ls=":", lw=1.5)
        bottom.set_xlabel("AO iteration")
        bottom.set_title(f"after 20: {y[-1] / glob - 1:.2%} above global", fontsize=9)
        if i == 0:
            top.set_ylabel("expected cost J^ (after iteration 1)")
            top.legend(fontsize=7)
            bottom.set_ylabel("excess over global (%)")
    fig.tight_layout()
    fig.savefig(path)


def format_convergence(conv_rows: Sequence[ConvergenceRow], slots: Sequence[int]) -> str:
    """The AO's distance above the global reference after its first and its last iteration, and
    rg-mpc's, at each slot of :func:`convergence`'s rows (one line per slot)."""
    lines = ["convergence (paper's AO, 20 iterations, no early stop): J^ above the global reference"]
    for slot in slots:
        sel = [r for r in conv_rows if r.slot == slot]
        if sel:
            first, last = next(r for r in sel if r.block == "drone"), sel[-1]
            lines.append(f"  slot {slot}: after iteration 1 {first.objective / first.global_objective - 1:+.2%}, "
                         f"after 20 {last.objective / last.global_objective - 1:+.2%}, "
                         f"rg-mpc {last.rg_mpc_objective / last.global_objective - 1:+.3%}")
    return "\n".join(lines)


def write_gap_outputs(rows: Sequence[GapRow], summary: Sequence[GapSummary], conv_rows: Sequence[ConvergenceRow],
                      out_dir: Path) -> None:
    """``gap_rows.csv``, ``gap_summary.csv`` and ``.md``, ``gap.png`` and, with convergence rows,
    ``convergence.csv`` and ``.png`` in ``out_dir``."""
    out_dir = Path(out_dir)
    write_rows([r.as_row() for r in rows], out_dir / "gap_rows.csv")
    write_rows([e.as_row() for e in summary], out_dir / "gap_summary.csv")
    (out_dir / "gap_summary.md").write_text(format_gap_table(summary) + "\n")
    plot_gaps(rows, out_dir / "gap.png")
    if conv_rows:
        write_rows([r.as_row() for r in conv_rows], out_dir / "convergence.csv")
        plot_convergence(conv_rows, out_dir / "convergence.png")

