"""``lawn benchmark``: the expert and the baselines on the same seeded episodes."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

from lawn_env import ScenarioConfig

from .evaluate import (SUMMARY_METRICS, TRANSIENT_SLOTS, evaluate, format_table, paired_cost_difference,
                       paired_cost_geometric, summarize, write_rows)
from .score import scores_by_policy

__all__ = ["run_benchmark", "plot_summary", "summary_markdown", "RESULT_METRICS", "TIMING_METRICS"]

#: The summary's deterministic metrics (the same seeds give the same digits on any machine) and its
#: measured ones (this machine's clock), in two tables.
RESULT_METRICS = tuple(m for m in SUMMARY_METRICS if not m[0].startswith("decision_time"))
TIMING_METRICS = tuple(m for m in SUMMARY_METRICS if m[0].startswith("decision_time"))


def run_benchmark(policies: Sequence[str], env_id: str, config: ScenarioConfig, episodes: int, seed: int,
                  out_dir: Path, workers: int = 1, progress: bool = True, transient_slots: int = TRANSIENT_SLOTS
                  ) -> tuple[list[dict], list[dict]]:
    """Run every policy on seeds ``seed .. seed+episodes-1``; write ``episodes.csv``,
    ``summary.csv``, ``summary.md`` and ``benchmark.png`` into ``out_dir``. With ``epa`` and
    ``rg-mpc`` among the policies, the summary has the normalized score (:mod:`training.score`);
    every policy is compared with the first, per seed, as a mean of relative differences and as a
    geometric mean of cost ratios (the deciding statistic, docs/benchmark.md)."""
    tasks = [(name, env_id, config, seed + i, {}) for name in policies for i in range(episodes)]
    rows = evaluate(tasks, workers=workers, progress=progress, desc="benchmark", transient_slots=transient_slots)
    out_dir = Path(out_dir)
    write_rows(rows, out_dir / "episodes.csv")  # the episodes first: a failed summary loses none of them
    summary = summarize(rows)
    paired = paired_cost_difference(rows, policies[0])
    geometric = paired_cost_geometric(rows, policies[0])
    scores = {policy: score for (_, _, policy), score in scores_by_policy(rows).items()}
    for entry in summary:
        mean, half = paired.get(entry["policy"], (float("nan"), float("nan")))
        entry[f"cost_vs_{policies[0]}"], entry[f"cost_vs_{policies[0]}_ci95"] = mean, half
        if entry["policy"] in geometric:
            g = geometric[entry["policy"]]
            entry[f"ratio_vs_{policies[0]}"], entry["ratio_low"], entry["ratio_high"] = g.ratio, g.low, g.high
            entry["seeds_won"] = g.won
        if entry["policy"] in scores:
            entry["score"], entry["score_low"], entry["score_high"] = scores[entry["policy"]][:3]
    write_rows(summary, out_dir / "summary.csv")
    (out_dir / "summary.md").write_text(summary_markdown(summary, paired, policies[0], scores, geometric))
    plot_summary(summary, out_dir / "benchmark.png",
                 title=f"{env_id}, K={config.num_agvs}, {episodes} seeds from {seed}: mean ± 95 % interval")
    return rows, summary


def summary_markdown(summary: list[dict], paired: dict, reference: str, scores: dict, geometric: dict) -> str:
    """The benchmark's summary as Markdown: the results table, which the same seeds reproduce digit
    for digit on any machine, then each policy's decision time, which is this machine's."""
    results = format_table(summary, metrics=RESULT_METRICS, paired=paired, reference=reference, scores=scores,
                           geometric=geometric)
    timing = format_table(summary, metrics=TIMING_METRICS)
    return f"{results}\n\nDecision time (median per episode; mean ± 95 % interval over the episodes), measured on the " \
           f"machine that ran it:\n\n{timing}\n"


def plot_summary(summary: list[dict], path: Path, title: str = "") -> None:
    """Bar chart of each summary metric with its 95 % interval."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(16, 3.6), dpi=110)
    FigureCanvasAgg(fig)
    names = [entry["policy"] for entry in summary]
    colors = [f"C{i}" for i in range(len(names))]
    for j, (key, label) in enumerate(SUMMARY_METRICS):
        ax = fig.add_subplot(1, len(SUMMARY_METRICS), j + 1)
        scale = 1e3 if key.startswith("decision_time") else 1.0
        means = [entry[key] * scale for entry in summary]
        errs = [entry[f"{key}_ci95"] * scale for entry in summary]
        ax.bar(names, means, yerr=errs, color=colors, capsize=4)
        ax.set_title(label.replace("(s)", "(ms)"), fontsize=10)
        ax.tick_params(axis="x", labelrotation=45, labelsize=8)
        positive = [m for m in means if m > 0]
        if key.endswith("_cost") and positive and max(positive) > 20 * min(positive):
            ax.set_yscale("log")
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
