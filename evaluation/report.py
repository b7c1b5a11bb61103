"""Markdown tables and figures from evaluation results and their statistics (:mod:`.stats`; the
cells' formats are :mod:`.cells`): the benchmark's summary, the learned protocol's table, the suite's
board, references, cost structure and per-task tables, the fleet-size and distillation tables, and
their figures. Nothing here plays an episode or reads a file; a table's targets come from the
protocol that owns them (:mod:`.protocols`); the pages' prose around the tables lives in ``docs/``."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from agents.base import JOINT

from .cells import (
    fmt_geometric,
    fmt_num,
    fmt_paired,
    fmt_pct,
    fmt_ranges,
    fmt_stat,
    fmt_tail,
    fmt_worst,
    format_score,
    markdown_table,
)
from .episode import TRANSIENT_SLOTS, Entry
from .seeds import TEST_RANGES
from .stats import (
    SCORE_HIGH,
    SCORE_LOW,
    SCORE_VERSION,
    SUMMARY_METRICS,
    TAIL_RATIO,
    RangeComparison,
    Score,
)

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from .rows import Key, RowStats, Statistics, SummaryRow, Versus

__all__ = ["RESULT_METRICS", "TIMING_METRICS", "format_table", "summary_markdown", "plot_summary", "mean_cell",
           "protocol_cells", "learned_table", "board_table", "references_table", "structure_table", "task_tables",
           "plot_profiles", "skipped_summary", "fleet_table", "distil_table"]

#: The summary's deterministic metrics (the same seeds give the same digits on any machine) and its
#: measured ones (this machine's clock), in two tables.
RESULT_METRICS = tuple(m for m in SUMMARY_METRICS if not m[0].startswith("decision_time"))
TIMING_METRICS = tuple(m for m in SUMMARY_METRICS if m[0].startswith("decision_time"))
#: The cost columns of the per-task and learned tables.
_COSTS = ("control_cost", "transient_cost", "sustained_cost")
Rows = Sequence[Mapping[str, Any]]  # the rows of a table other than episodes' (summaries, per-slot means)


def format_table(rows: Sequence[SummaryRow], metrics: Sequence[tuple[str, str]] = SUMMARY_METRICS,
                 comparisons: bool = True) -> str:
    """A Markdown table: mean ± 95 % interval per metric (decision time in ms) and, with
    ``comparisons``, each column the rows hold: the score (:func:`.stats.normalized_score`) and the
    cost against the rows' reference (the mean relative difference; the geometric comparison, the
    deciding statistic)."""
    reference = next((r.reference for r in rows if r.reference is not None), None)
    scores = comparisons and any(r.score is not None for r in rows)
    paired = comparisons and any(r.paired is not None for r in rows)
    geometric = comparisons and any(r.geometric is not None for r in rows)
    header = ["policy", "episodes"] + [label.replace("(s)", "(ms)") for _, label in metrics]
    if scores:
        header.insert(3, f"score v{SCORE_VERSION} [95 %]")
    if paired:
        header.append(f"cost vs {reference} (paired)")
    if geometric:
        header.append(f"cost vs {reference} (geometric [95 %], seeds won)")
    table = []
    for row in rows:
        cells = [row.policy, str(row.episodes)]
        for key, _ in metrics:
            scale = 1e3 if key.startswith("decision_time") else 1.0
            mean, half = row.means[key].mean * scale, row.means[key].half * scale
            if key == "diverged":  # a flag per episode (lawn_env.core.DIVERGENCE_DISTANCE_M): how many of them
                cells.append("n/a" if not math.isfinite(mean) else f"{round(mean * row.episodes)}")
            else:
                cells.append(f"{fmt_stat(mean)} ± {fmt_stat(half)}")
        if scores:
            cells.insert(3, format_score(row.score))
        if paired:
            mean, half = row.paired or (math.nan, math.nan)
            cells.append("–" if row.policy == reference else f"{mean * 100:+.1f} % ± {half * 100:.1f} %")
        if geometric:
            cells.append("–" if row.policy == reference else fmt_geometric(row.geometric))
        table.append(cells)
    return markdown_table(header, table)


def summary_markdown(rows: Sequence[SummaryRow]) -> str:
    """The benchmark's summary as Markdown: the results table, which the same seeds reproduce digit
    for digit on any machine, then each policy's decision time, which is this machine's."""
    results = format_table(rows, metrics=RESULT_METRICS)
    timing = format_table(rows, metrics=TIMING_METRICS, comparisons=False)
    return (f"{results}\n\nDecision time (median per episode; mean ± 95 % interval over the episodes), measured on the "
            f"machine that ran it:\n\n{timing}\n")


def plot_summary(rows: Sequence[SummaryRow], path: Path, title: str = "") -> Figure:
    """Bar chart of each summary metric with its 95 % interval, one panel per metric, the policies'
    names upright under every panel (the figure widens with the number of policies so that they never
    overlap); the ``diverged`` panel only when some episode diverged (the title says when none did).
    Returns the figure, which is also written to ``path``."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    names = [row.policy for row in rows]
    colors = [f"C{i % 10}" for i in range(len(names))]
    diverged = [row.means["diverged"].mean for row in rows]
    metrics = [(key, label) for key, label in SUMMARY_METRICS if key != "diverged" or any(d > 0 for d in diverged)]
    notes = [title] if title else []
    if all(d == 0 for d in diverged):
        notes.append("no episode diverged")
    fig = Figure(figsize=(max(16.0, len(metrics) * (0.8 + 0.2 * len(names))), 4.6), dpi=110)
    FigureCanvasAgg(fig)
    for j, (key, label) in enumerate(metrics):
        ax = fig.add_subplot(1, len(metrics), j + 1)
        scale = 1e3 if key.startswith("decision_time") else 1.0
        means = [row.means[key].mean * scale for row in rows]
        errs = [row.means[key].half * scale for row in rows]
        ax.bar(names, means, yerr=errs, color=colors, capsize=3)
        ax.set_title(label.replace("(s)", "(ms)"), fontsize=10)
        ax.set_xlim(-0.6, len(names) - 0.4)
        ax.tick_params(axis="x", labelrotation=90, labelsize=8)
        ax.tick_params(axis="y", labelsize=8)
        positive = [m for m in means if m > 0]
        if key.endswith("_cost") and positive and max(positive) > 20 * min(positive):
            ax.set_yscale("log")
    if notes:
        fig.suptitle("; ".join(notes), fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    return fig


def mean_cell(row: RowStats | None, metric: str = "control_cost") -> str:
    """``mean ± 95 % half-width`` of a cost metric of a row (``n/a`` for no row)."""
    mean, half = row.means[metric] if row is not None else (math.nan, math.nan)
    return f"{fmt_num(mean)} ± {fmt_num(half)}"


def protocol_cells(stats: Statistics, entry: Entry, task: str = "default") -> dict[str, str]:
    """The cells every learned-protocol table shows for an entry: its anchor, control cost, score,
    paired difference against the best expert and against its own anchor, and its worst seed
    against the anchor."""
    policy, env, anchor = entry
    row = stats.row(task, env, policy)
    cells = {"anchor": anchor or "–", **{name: mean_cell(row, m) for name, m in zip(_CELLS, _COSTS, strict=True)},
             "score": format_score(row.score if row else None), "vs_ref": "–", "vs_anchor": "–", "worst": "–",
             "geo_ref": "–", "geo_anchor": "–"}
    ref = stats.versus((task, env, policy), (task, env, SCORE_HIGH))
    if policy != SCORE_HIGH and ref is not None:
        cells["vs_ref"], cells["geo_ref"] = fmt_paired(*ref.paired), fmt_geometric(ref.geometric)
    own = stats.versus((task, env, policy), (task, env, anchor)) if anchor else None
    if own is not None:
        cells["vs_anchor"], cells["geo_anchor"] = fmt_paired(*own.paired), fmt_geometric(own.geometric)
        cells["worst"] = fmt_pct(max(own.relative))
    return cells


_CELLS = ("cost", "transient", "sustained")
_LEARNED_CELLS = ("anchor", "cost", "transient", "sustained", "score", "geo_ref", "geo_anchor", "vs_ref", "vs_anchor",
                  "worst")


def learned_table(stats: Statistics, entries: Sequence[Entry], labels: Mapping[str, str] | None = None) -> str:
    """The learned protocol's Markdown table of ``entries``."""
    header = ["policy", "env", "acts around", "control cost", "transient", "sustained",
              f"score v{SCORE_VERSION} [95 %]", f"vs {SCORE_HIGH} (geometric, seeds won)",
              "vs own anchor (geometric, seeds won)",
              f"vs {SCORE_HIGH} (paired mean)", "vs own anchor (paired mean)", "worst seed vs own anchor"]
    table = []
    for entry in entries:
        c = protocol_cells(stats, entry)
        table.append([(labels or {}).get(entry.policy, entry.policy), entry.env, *(c[k] for k in _LEARNED_CELLS)])
    split = stats.transient_slots or TRANSIENT_SLOTS
    note = (f"{len(stats.seeds)} test seeds; control cost split into the transient (slots 0-{split - 1}) and the "
            f"sustained part (slots {split} on); score v{SCORE_VERSION}: 0 = {SCORE_LOW}, 100 = {SCORE_HIGH} "
            "(evaluation/stats.py); geometric columns (the deciding statistic, docs/benchmark.md): the geometric "
            "mean of the per-seed cost ratios - 1 with its 95 % bootstrap interval and the share of seeds won; "
            "paired-mean columns: the mean per-seed relative difference and its 95 % t-interval.")
    return f"{markdown_table(header, table)}\n\n{note}"


def board_table(stats: Statistics, rows: Sequence[Entry], tasks: Sequence[str],
                skipped: Mapping[tuple[str, str], str]) -> str:
    """The leaderboard, a row per entry (a policy on its env) in order: its score per task and the IQM
    over tasks with its stratified bootstrap interval (``n/a`` where it cannot act, :func:`skipped_summary`)."""
    board = []
    for p, env, _ in rows:
        cells = ["n/a" if (task, p) in skipped else format_score(_score(stats, task, env, p)) for task in tasks]
        iqm = stats.aggregate(env, p, tasks)
        n = iqm.n
        overall = "–" if n == 0 else format_score(iqm)
        board.append([p, env, *cells, overall + ("" if n in (0, len(tasks)) else f" ({n} task{'s' * (n != 1)})")])
    return markdown_table(["policy", "env", *tasks, "IQM over tasks [95 %]"], board)


def _score(stats: Statistics, task: str, env: str, policy: str) -> Score | None:
    row = stats.row(task, env, policy)
    return row.score if row is not None else None


def references_table(stats: Statistics, tasks: Sequence[str]) -> str:
    """The references' costs per task and env, their gap and how it varies over the seeds."""
    refs = []
    for task in tasks:
        for env in stats.envs(task):
            low, high = stats.row(task, env, SCORE_LOW), stats.row(task, env, SCORE_HIGH)
            gap = stats.versus((task, env, SCORE_LOW), (task, env, SCORE_HIGH))
            if low is None or high is None or gap is None:
                continue
            per_seed = gap.relative
            refs.append([task, env, str(low.seeds), mean_cell(low), mean_cell(high),
                         fmt_num(low.means["control_cost"][0] - high.means["control_cost"][0]),
                         f"{fmt_pct(min(per_seed))} to {fmt_pct(max(per_seed))}", str(sum(g <= 0 for g in per_seed))])
    return markdown_table(["task", "env", "episodes", f"{SCORE_LOW} cost", f"{SCORE_HIGH} cost", "gap (mean)",
                           f"per-seed gap / {SCORE_HIGH} cost, min to max", f"seeds where {SCORE_LOW} costs no more"],
                          refs)


def structure_table(stats: Statistics, tasks: Sequence[str], references: Sequence[str]) -> str:
    """Per task, what decides it on ``lawn/Joint-v1``: the best expert's control cost, its transient and
    sustained parts (the sustained share), and each reference row (the noise floor, the headroom rows)
    against it."""
    table = []
    for task in tasks:
        high = stats.row(task, JOINT, SCORE_HIGH)
        if high is None:
            continue
        share = high.totals["sustained_cost"] / high.totals["control_cost"]
        cells = [mean_cell(high, m) for m in _COSTS]
        cells[2] += f" ({share * 100:.0f} %)"
        for p in references:
            vs = stats.versus((task, JOINT, p), (task, JOINT, SCORE_HIGH))
            cells.append(fmt_geometric(vs.geometric) if vs is not None else "–")
        table.append([task, *cells])
    header = ["task", f"{SCORE_HIGH} cost", "transient", "sustained (share)",
              *(f"{p} vs {SCORE_HIGH} (geometric, seeds won)" for p in references)]
    return markdown_table(header, table)


def task_tables(stats: Statistics, names: Sequence[str], tasks: Sequence[str],
                skipped: Mapping[tuple[str, str], str]) -> str:
    """One Markdown table per task: every row (``names`` in order, on each env of the task) with its
    control cost, its transient and sustained parts, the score, and the comparison with the best
    expert on the same env (geometric and paired mean)."""
    out = []
    for task in tasks:
        table = []
        for env in stats.envs(task):
            for p in names:
                row = stats.row(task, env, p)
                if (task, p) in skipped or row is None:
                    continue
                cells = [mean_cell(row, m) for m in _COSTS] + [format_score(row.score)]
                vs = stats.versus((task, env, p), (task, env, SCORE_HIGH))
                if p == SCORE_HIGH or vs is None:
                    cells += ["–", "–"] if p == SCORE_HIGH else ["n/a", "n/a"]
                else:
                    cells += [fmt_geometric(vs.geometric), fmt_paired(*vs.paired)]
                table.append([p, env, *cells])
        header = ["policy", "env", "control cost", "transient", "sustained", f"score v{SCORE_VERSION} [95 %]",
                  f"vs {SCORE_HIGH} (geometric, seeds won)", f"vs {SCORE_HIGH} (paired mean)"]
        out.append(f"**{task}**\n\n" + markdown_table(header, table))
    return "\n\n".join(out)


def plot_profiles(per_slot: Rows, path: Path, tasks: Sequence[str], transient_slots: int = TRANSIENT_SLOTS) -> Path:
    """The mean stage cost per slot of every row on ``lawn/Joint-v1`` (the agents on their own env),
    one panel per task, log scale; from the rows of ``per_slot.csv`` (:func:`.run.per_slot_profile`)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    cols = min(3, len(tasks))
    nrows = -(-len(tasks) // cols)
    fig = Figure(figsize=(5.2 * cols, 3.6 * nrows), dpi=100)
    FigureCanvasAgg(fig)
    policies = list(dict.fromkeys(str(r["policy"]) for r in per_slot))
    styles = {p: (f"C{i % 10}", "-" if i < 10 else "--") for i, p in enumerate(policies)}
    for j, task in enumerate(tasks):
        ax = fig.add_subplot(nrows, cols, j + 1)
        for p in policies:
            mine = [r for r in per_slot if r["task"] == task and r["policy"] == p
                    and (r["env"] == JOINT or p.startswith(("zoo:", "sb3:", "bc:", "marl:")))]
            if not mine:
                continue
            color, line = styles[p]
            ax.plot([int(r["slot"]) for r in mine], [float(r["mean_stage_cost"]) for r in mine], line, color=color,
                    lw=1.0, label=p)
        ax.axvline(transient_slots - 0.5, color="0.6", lw=0.8, ls=":")
        ax.set_yscale("log")
        ax.set_title(task, fontsize=10)
        ax.set_xlabel("slot", fontsize=8)
        ax.set_ylabel("mean stage cost", fontsize=8)
        ax.tick_params(labelsize=7)
    handles, labels = fig.axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=min(6, len(labels)), fontsize=7, frameon=False)
    fig.tight_layout(rect=(0, 0.04 + 0.02 * (len(labels) // 6), 1, 1))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    return path


def skipped_summary(skipped: Mapping[tuple[str, str], str]) -> list[str]:
    """One line per task of the policies that cannot act there, with the first one's reason."""
    by_task: dict[str, list[str]] = {}
    for task, policy in skipped:
        by_task.setdefault(task, []).append(policy)
    return [f"on `{task}`: {', '.join(ps)} ({skipped[(task, ps[0])]})" for task, ps in by_task.items()]


def _versus(stats: Statistics, key: Key, reference: Key) -> Versus:
    """A comparison of two rows the caller found."""
    vs = stats.versus(key, reference)
    assert vs is not None, (key, reference)
    return vs


def fleet_table(stats: Statistics, agents: Sequence[Entry], sizes: Mapping[int, int],
                target: Callable[[str, int, RangeComparison], str]) -> str:
    """Per env and K: the noise-floor row and every agent (on its env) against dv-mpc on both test
    ranges, the tail, the worst seed, ``target(policy, K, comparison)`` (the verdict of the protocol's
    target, "–" for a row without one) and the decision times."""
    table = []
    noise = f"noise:{SCORE_HIGH}"
    for env in dict.fromkeys(a.env for a in agents):
        for policy in [noise, *(a.policy for a in agents if a.env == env)]:
            for k in sizes:
                task = f"k{k}"
                mine, ref = stats.row(task, env, policy), stats.row(task, env, SCORE_HIGH)
                if mine is None or ref is None:
                    continue
                c = _versus(stats, (task, env, policy), (task, env, SCORE_HIGH)).ranges
                table.append([policy, env, str(k), str(mine.seeds), mean_cell(mine), mean_cell(ref), fmt_ranges(c),
                              fmt_tail(c), fmt_worst(c), target(policy, k, c), f"{mine.decision_ms:.3g}",
                              f"{ref.decision_ms / mine.decision_ms:.1f}×"])
    header = ["policy", "env", "K", "seeds", "control cost", f"{SCORE_HIGH} cost",
              f"vs {SCORE_HIGH}, geometric [95 %]: seeds {TEST_RANGES[0]}.. / {TEST_RANGES[1]}..",
              f"seeds > {TAIL_RATIO:g}× {SCORE_HIGH}", "worst seed", "target (both ranges)", "decision time (ms)",
              f"{SCORE_HIGH} / policy time"]
    return markdown_table(header, table)


def distil_table(stats: Statistics, agents: Mapping[str, tuple[str, str]], tasks: Sequence[str], reference_env: str,
                 target: Callable[[str, RangeComparison, RangeComparison, float], str]) -> str:
    """Per agent (``{policy: (label, env)}``) and task: its cost against ``rg-mpc`` and ``dv-mpc``
    (played on ``reference_env``, the same scenario and seeds) on both ranges, the tail and worst
    seed against dv-mpc, the decision time and ``target(policy, vs rg-mpc, vs dv-mpc, ms)``, the verdict
    of the protocol's targets for that agent ("–" for one without)."""
    table = []
    for policy, (label, env) in agents.items():
        for task in tasks:
            mine = stats.row(task, env, policy)
            rg_row, dv_row = stats.row(task, reference_env, "rg-mpc"), stats.row(task, reference_env, SCORE_HIGH)
            if mine is None or rg_row is None or dv_row is None:
                continue
            rg = _versus(stats, (task, env, policy), (task, reference_env, "rg-mpc")).ranges
            dv = _versus(stats, (task, env, policy), (task, reference_env, SCORE_HIGH)).ranges
            table.append([label, env, task, str(mine.seeds), mean_cell(mine), fmt_num(dv_row.means["control_cost"][0]),
                          fmt_ranges(rg), fmt_ranges(dv), fmt_tail(dv), fmt_worst(dv), f"{mine.decision_ms:.3g}",
                          target(policy, rg, dv, mine.decision_ms)])
    header = ["agent", "env", "task", "seeds", "control cost", f"{SCORE_HIGH} cost",
              f"vs rg-mpc, geometric [95 %]: seeds {TEST_RANGES[0]}.. / {TEST_RANGES[1]}..",
              f"vs {SCORE_HIGH}, same", f"seeds > {TAIL_RATIO:g}× {SCORE_HIGH}", f"worst seed vs {SCORE_HIGH}",
              "decision time (ms)", "target: < 0 vs rg-mpc, ≤ +3 % vs dv-mpc, ≤ 1 ms"]
    return markdown_table(header, table)
