"""The shipped learned agents: how they compare and what is exported, in four stages a test can
call one by one: :func:`evaluate_zoo` (every finished run of every recipe of :mod:`training.recipes`
by the learned protocol of :mod:`evaluation.protocols`), :func:`zoo_tables` (the table cells and the
run each recipe ships, selected on the validation seeds), :func:`render_zoo` (Markdown;
:func:`plot_curves` the learning curves) and :func:`export_zoo` (``agents/zoo/<name>``: policy
weights and observation statistics only). ``lawn zoo build`` (:func:`paper.learned.build_zoo`) runs
them and writes ``docs/LEARNED.md``; ``lawn zoo list`` shows the shipped agents (:func:`format_zoo_list`)."""

from __future__ import annotations

import math
import shutil
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from agents.learned import ZOO_DIR, export_agent, zoo_agents
from agents.runs import AgentRecord, Benchmark, RunDir, read_run
from evaluation.cells import fmt_num, fmt_paired, fmt_pct, markdown_table
from evaluation.episode import Entry, EpisodeResult, Play
from evaluation.protocols import execute, learned_protocol
from evaluation.report import protocol_cells
from evaluation.rows import Statistics
from evaluation.seeds import TEST_EPISODES
from evaluation.stats import SCORE_HIGH, SCORE_VERSION, Score, mean_ci, paired, verdict

from .recipes import RECIPES, Recipe, finished
from .validation import best_validation, read_learning_curve, run_key, selected_at

__all__ = ["finished_runs", "evaluate_zoo", "zoo_tables", "render_zoo",
           "ZooMarkdown", "plot_curves", "export_zoo", "format_zoo_list", "ZooEvaluation", "ZooTables", "Shipped"]


@dataclass
class ZooEvaluation:
    """Stage 1 (:func:`evaluate_zoo`): the finished runs of every recipe and their episodes by the
    learned protocol, beside the references and each agent's anchor on the same test seeds."""

    found: list[tuple[Recipe, list[Path]]]
    runs: dict[Path, RunDir]
    entries: list[Entry]
    rows: list[EpisodeResult]
    stats: Statistics
    episodes: int

    @property
    def envs(self) -> list[str]:
        return list(dict.fromkeys(e.env for e in self.entries))

    def entry(self, policy: str, env: str) -> Entry:
        """The protocol's entry of ``policy`` on ``env`` (with its anchor)."""
        return next(e for e in self.entries if e.policy == policy and e.env == env)

    def score(self, policy: str, env: str) -> Score:
        """The policy's normalized score on ``env`` (its references beside it on the same seeds)."""
        row = self.stats.row("default", env, policy)
        if row is None or row.score is None:
            raise ValueError(f"{policy} on {env}: no score (its references did not run beside it)")
        return row.score

    def anchor(self, policy: str) -> str:
        """The anchor a learned agent acts around; "" (no seeds, a NaN comparison) for one that records none."""
        return next((e.anchor for e in self.entries if e.policy == policy and e.anchor), "")


@dataclass
class Shipped:
    """A recipe's run selected on the validation seeds, with what its export records."""

    recipe: Recipe
    run_dir: Path
    specs: list[AgentRecord]
    env: str
    across: tuple[float, float]  # mean and 95 % half-width of vs-own-anchor across training seeds


@dataclass
class ZooTables:
    """Stage 2 (:func:`zoo_tables`): the cells of the recipe table (experts, anchors, each recipe's
    shipped run) and of the per-run table, and the run each recipe ships."""

    recipe_rows: list[dict[str, str]]
    run_rows: list[dict[str, str]]
    shipped: list[Shipped]
    sources: list[str]
    floor: list[str]
    episodes: int


def finished_runs(runs: Path, recipes: Mapping[str, Recipe] | None = None) -> list[tuple[Recipe, list[Path]]]:
    """Every recipe with at least one finished run in ``runs``, with those runs' directories."""
    recipes = RECIPES if recipes is None else recipes
    found = [(r, [runs / r.name / f"seed-{s}" for s in r.seeds if finished(runs / r.name / f"seed-{s}", r.timesteps)])
             for r in recipes.values()]
    found = [(r, dirs) for r, dirs in found if dirs]
    if not found:
        raise ValueError(f"{runs}: no finished recipe runs of {', '.join(recipes)} (lawn zoo train --runs {runs} "
                         "trains them)")
    return found


def evaluate_zoo(found: list[tuple[Recipe, list[Path]]], episodes: int = TEST_EPISODES, workers: int = 2,
                 progress: bool = True) -> ZooEvaluation:
    """Stage 1: every run by the learned protocol on test seeds 0..episodes-1
    (:func:`evaluation.protocols.learned_protocol`)."""
    run = {d: read_run(d) for _, dirs in found for d in dirs}
    protocol = learned_protocol([run[d].policy_name for _, dirs in found for d in dirs], episodes)
    outcome = execute(protocol, Play(workers, progress))
    return ZooEvaluation(found, run, protocol.entries, outcome.results, outcome.stats, episodes)


def zoo_tables(ev: ZooEvaluation) -> ZooTables:
    """Stage 2: the table cells, per env: the experts and anchors, then each recipe's shipped run
    (the seed whose selected validation is lowest); every run in the per-run table."""
    recipe_rows, run_rows, shipped = [], [], []
    for env in ev.envs:
        learned = ("sb3:", "bc:", "marl:")
        for policy in [e.policy for e in ev.entries if e.env == env and not e.policy.startswith(learned)]:
            how = "expert" if ":" not in policy else "zero action"
            recipe_rows.append(_cells(ev, policy, env, policy, how, "–"))
        for r, dirs in ev.found:
            if r.evaluated_on != env:
                continue
            validation = [best_validation(d) for d in dirs]
            chosen = dirs[int(np.argmin([run_key(d) for d in dirs]))]
            gains = [paired(ev.rows, ev.runs[d].policy_name, ev.anchor(ev.runs[d].policy_name), env) for d in dirs]
            across = mean_ci(g[0] for g in gains)
            run_rows += [_run_cells(ev, r, d, best, d == chosen, env) for d, best in zip(dirs, validation, strict=True)]
            specs = [ev.runs[d].record for d in dirs]
            algo = {"bc": "BC", "fleet": "DAgger"}.get(r.algo, r.algo.upper())
            steps = specs[0].steps(r.timesteps)
            budget = (f"{algo}, {steps:,} steps{'' if r.num_agvs == 4 else f' at K = {r.num_agvs}'}, "
                      f"{np.mean([s.run_seconds for s in specs]):.0f} s")
            label = f"{r.label} (`zoo:{r.name}`, seed {ev.runs[chosen].record.require('seed')})"
            recipe_rows.append(_cells(ev, ev.runs[chosen].policy_name, env, label, budget,
                                      f"{fmt_paired(*across)} ({len(dirs)} seeds)"))
            shipped.append(Shipped(r, chosen, specs, env, across))
    sources = sorted({(rd.record.versions or {}).get("source", "not recorded") for rd in ev.runs.values()})
    floor = [f"`{a}` on {env} {fmt_paired(*paired(ev.rows, SCORE_HIGH, a, env))}" for a, env, _ in ev.entries
             if a.startswith("anchor:")]
    return ZooTables(recipe_rows, run_rows, shipped, sources, floor, ev.episodes)


_RECIPE_COLUMNS = ("label", "env", "how", "anchor", "cost", "score", "vs_ref", "vs_anchor", "across")
_RUN_COLUMNS = ("recipe", "seed", "anchor", "validation", "score", "vs_ref", "vs_anchor", "worst", "wall_time")


def _cells(ev: ZooEvaluation, policy: str, env: str, label: str, how: str, across: str) -> dict[str, str]:
    """One row of the recipe table: an expert, an anchor or a recipe's shipped run."""
    cells = protocol_cells(ev.stats, ev.entry(policy, env))
    return {"label": label, "env": env, "how": how, **cells, "across": across}


def _run_cells(ev: ZooEvaluation, r: Recipe, run_dir: Path, best: Mapping[str, Any], chosen: bool,
               env: str) -> dict[str, str]:
    """One row of the per-run table."""
    spec = ev.runs[run_dir].record
    c = protocol_cells(ev.stats, ev.entry(ev.runs[run_dir].policy_name, env))
    vs = fmt_pct(best["vs_reference"]) if "vs_reference" in best else "–"
    episodes = spec.eval_episodes if spec.eval_episodes is not None else "?"
    validation = f"{vs} ({fmt_num(best['control_cost'])}, {episodes})"
    return {"recipe": f"`{r.name}`{' (shipped)' if chosen else ''}", "seed": str(spec.require("seed")),
            "anchor": c["anchor"], "validation": validation,
            "score": c["score"], "vs_ref": c["vs_ref"], "vs_anchor": c["vs_anchor"], "worst": c["worst"],
            "wall_time": f"{spec.run_seconds:.0f} s"}


class ZooMarkdown(NamedTuple):
    """The zoo's tables as Markdown: the recipe table (with its note) and the per-run table."""

    recipes: str
    runs: str


def render_zoo(tables: ZooTables) -> ZooMarkdown:
    """Stage 3: the recipe table (with its note on seeds, sources and the expert against each
    anchor) and the per-run table, as Markdown."""
    head = ["agent", "env", "algorithm, budget per run", "acts around", "control cost",
            f"score v{SCORE_VERSION} [95 %]", f"vs {SCORE_HIGH} (paired)", "vs own anchor (paired)",
            "vs own anchor, mean over training seeds"]
    runs_head = ["recipe", "training seed", "acts around", "selected validation: vs rg-mpc (cost, episodes)",
                 f"score v{SCORE_VERSION}", f"vs {SCORE_HIGH} (paired)", "vs own anchor (paired)",
                 "worst test seed vs own anchor", "wall time"]
    n = tables.episodes
    note = (f"{n} test seeds (0-{n - 1}); training runs made at: {'; '.join(tables.sources)}. `{SCORE_HIGH}` itself "
            f"against each anchor (the \"vs own anchor\" of a perfect clone of the expert): {'; '.join(tables.floor)}.")
    table = markdown_table(head, ([row[k] for k in _RECIPE_COLUMNS] for row in tables.recipe_rows))
    per_run = markdown_table(runs_head, ([row[k] for k in _RUN_COLUMNS] for row in tables.run_rows))
    return ZooMarkdown(f"{table}\n\n{note}", per_run)


def export_zoo(tables: ZooTables, ev: ZooEvaluation, target: Path = ZOO_DIR) -> list[Path]:
    """Stage 4: each recipe's shipped run as ``target/<name>`` (policy weights, statistics, agent.json)."""
    return [_export(s, ev, Path(target)) for s in tables.shipped]


def plot_curves(found: list[tuple[Recipe, list[Path]]], reference: dict[str, float], path: Path) -> None:
    """Validation cost against training steps, every seed of every recipe, with rg-mpc's cost on
    the same validation seeds."""

    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    cols = min(4, len(found))
    rows_ = math.ceil(len(found) / cols)
    fig = Figure(figsize=(4.0 * cols, 3.2 * rows_), dpi=110)
    FigureCanvasAgg(fig)
    for j, (r, dirs) in enumerate(found):
        ax = fig.add_subplot(rows_, cols, j + 1)
        for d in dirs:
            rows = read_learning_curve(d)
            ax.plot([x["timesteps"] for x in rows], [x["control_cost"] for x in rows], "-o", ms=2, label=d.name)
        ax.axhline(reference[r.evaluated_on], color="k", ls="--", lw=1, label="rg-mpc")
        ax.set_yscale("log")
        ax.set_title(r.name, fontsize=9)
        ax.set_xlabel("environment steps", fontsize=8)
        if j % cols == 0:
            ax.set_ylabel("validation control cost", fontsize=8)
        ax.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(path)


def _export(s: Shipped, ev: ZooEvaluation, target_dir: Path) -> Path:
    r, run = s.recipe, ev.runs[s.run_dir]
    policy, episodes = run.policy_name, ev.episodes
    anchor = ev.anchor(policy) or None
    record = {
        "name": r.name, "label": r.label, "trained_on": r.env_id, "evaluated_on": s.env,
        "command": r.command(), "budget_steps": s.specs[0].steps(r.timesteps),
        "training_seeds": [spec.require("seed") for spec in s.specs], "shipped_seed": run.record.require("seed"),
        "selected_on": "lowest paired relative difference against rg-mpc on the validation seeds (500000 + i), "
                       "never the test seeds",
        "selected_at_steps": selected_at(s.run_dir),
        "wall_time_s": [round(spec.run_seconds, 1) for spec in s.specs],
        "benchmark": {"test_seeds": f"0-{episodes - 1}", "reference": SCORE_HIGH, "anchor": anchor,
                      "score_version": SCORE_VERSION, "score": list(ev.score(policy, s.env)[:3]),
                      "shipped_vs_reference": list(paired(ev.rows, policy, SCORE_HIGH, s.env)),
                      "shipped_vs_anchor": list(paired(ev.rows, policy, ev.anchor(policy), s.env)),
                      "across_training_seeds_vs_anchor": list(s.across)},
    }
    target = target_dir / r.name
    if target.exists():
        shutil.rmtree(target)
    export_agent(s.run_dir, target, record)
    return target


def _rate(rec: AgentRecord) -> str:
    """`` at N steps/s`` of a shipped agent's training runs ("" where not recorded)."""
    return f" at {rec.steps_per_s:,.0f} steps/s" if rec.steps_per_s else ""


def format_zoo_list() -> str:
    agents = zoo_agents()
    if not agents:
        return "no shipped agents (lawn zoo build exports them)"
    lines = []
    for name, rec in agents.items():
        trainer = rec.trainer or (RECIPES[name].algo if name in RECIPES else rec.algo)
        algo = trainer if trainer == rec.algo else f"{trainer}, a {rec.algo} network"
        bench = rec.benchmark or Benchmark()
        ship = bench.shipped_vs_reference or [math.nan, math.nan]
        gain = bench.shipped_vs_anchor or [math.nan, math.nan]
        lines.append(f"zoo:{name}  {rec.label or ''}")
        lines.append(f"  drives {rec.evaluated_on} (trained on {rec.trained_on}, {algo}), "
                     f"{rec.budget_steps or 0:,} steps{_rate(rec)}, training seeds {rec.training_seeds}, "
                     f"shipped seed {rec.shipped_seed}")
        if rec.selected_at_steps == 0 and trainer not in ("bc", "fleet"):
            lines.append("  ships its start: no validation beat the policy it started from (selected at 0 steps)")
        if bench.tasks is not None:  # a steady-task agent: geometric change per task and test range
            for task, refs in bench.tasks.items():
                cells = ", ".join(f"vs {ref} {' / '.join(fmt_pct(x) for x in changes)}"
                                  for ref, changes in refs.items())
                lines.append(f"  {task}, test seeds {bench.test_seeds} (geometric, per range): {cells}")
        else:
            same = verdict(gain[0], gain[1], "negative") == "not significant"  # no measured change from its anchor
            lines.append(f"  test seeds {bench.test_seeds}: cost vs {bench.reference or 'rg-mpc'} {fmt_paired(*ship)}, "
                         f"vs its anchor {bench.anchor or '?'} {fmt_paired(*gain)}"
                         + (" (no different from its anchor)" if same else "")
                         + f", score v{bench.score_version or '?'} {(bench.score or [math.nan])[0]:.1f} "
                         f"(recorded when the zoo was built; the leaderboard scores v{SCORE_VERSION})")
        lines.append(f"  trained with: {rec.command}")
    return "\n".join(lines)


