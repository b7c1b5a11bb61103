"""The learners' ladder (docs/LEARNED.md, "The ladder"): on every rung of :data:`lawn_env.presets.LADDER`,
the prior its scratch recipe starts from (the zero action of the recipe's interface), ``dv-mpc`` and
each training seed's validation-selected run, on both test ranges; the share of the prior's gap to
``dv-mpc`` each run closes, and the learning curves.

The gap closed is measured on the log of the cost, geometric over seeds::

    100 x mean_s(log prior_s - log agent_s) / mean_s(log prior_s - log dv-mpc_s)

with a 95 % percentile bootstrap interval over the seeds (the three costs of a seed resampled
together). 100 % is ``dv-mpc``'s cost, 0 % the prior's; above 100 % the agent is cheaper than ``dv-mpc``.

    python -m paper.ladder --runs runs/agents --out runs/ladder [--episodes 100] [--workers 2] [--overwrite]

writes ``ladder.md`` (the table the page's ``zoo-ladder`` block holds), ``ladder.csv`` (every episode)
and ``ladder.png`` (the curves).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

from agents.anchors import anchor_name
from agents.runs import read_run
from evaluation.cells import markdown_table
from evaluation.episode import EpisodeResult, EpisodeSpec, write_results
from evaluation.run import evaluate
from evaluation.seeds import TEST_EPISODES, TEST_RANGES, range_of, test_seeds
from evaluation.stats import BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED, paired_geometric
from lawn_env import presets
from lawn_env.interface import resolve_interface
from training.recipes import RECIPES, Recipe, finished
from training.validation import read_learning_curve, run_key, selection_of

__all__ = ["EXPERT", "ladder_recipes", "gap_closed", "Gap", "RungResult", "evaluate_ladder", "render_ladder",
           "plot_ladder", "Ladder", "main"]

#: What every rung's gap is measured to.
EXPERT = "dv-mpc"
#: The files ``main`` writes into ``--out``.
OUTPUTS = ("ladder.md", "ladder.csv", "ladder.png")


def ladder_recipes() -> list[tuple[presets.Rung, Recipe]]:
    """Each rung with the scratch recipe that learns on it (its preset and env)."""
    out = []
    for rung in presets.LADDER:
        match = [r for r in RECIPES.values() if r.name.endswith("-scratch") and r.preset == rung.preset
                 and r.env_id == rung.env_id]
        if len(match) != 1:
            raise ValueError(f"rung {rung.preset} on {rung.env_id}: {len(match)} scratch recipes, expected one")
        out.append((rung, match[0]))
    return out


@dataclass(frozen=True)
class Gap:
    """The share of the prior's log-cost gap to the expert an agent closes (percent), its 95 % interval
    and the seeds."""

    closed: float
    low: float
    high: float
    seeds: int

    def cell(self) -> str:
        return f"{self.closed:.0f} % [{self.low:.0f}, {self.high:.0f}]" if math.isfinite(self.low) else \
            f"{self.closed:.0f} %"


def gap_closed(agent: Mapping[int, float], prior: Mapping[int, float], expert: Mapping[int, float],
               resamples: int = BOOTSTRAP_RESAMPLES) -> Gap:
    """:class:`Gap` of ``agent`` on the seeds all three cost maps hold (costs > 0); the interval is
    NaN below 3 seeds and where the expert's gap to the prior changes sign within the resamples' range."""
    seeds = sorted(s for s in agent if s in prior and s in expert)
    if not seeds:
        raise ValueError("gap_closed: the agent, the prior and the expert share no seed")
    p, a, e = (np.log([float(m[s]) for s in seeds]) for m in (prior, agent, expert))
    gained, gap = p - a, p - e
    closed = 100.0 * gained.mean() / gap.mean()
    if len(seeds) < 3:
        return Gap(float(closed), math.nan, math.nan, len(seeds))
    from scipy import stats

    res = stats.bootstrap((gained, gap), lambda g, d, axis=-1: 100.0 * g.mean(axis) / d.mean(axis), paired=True,
                          vectorized=True, n_resamples=resamples, method="percentile",
                          random_state=np.random.default_rng(BOOTSTRAP_SEED))
    return Gap(float(closed), float(res.confidence_interval.low), float(res.confidence_interval.high), len(seeds))


@dataclass
class RungResult:
    """One rung's episodes: the prior's, the expert's and each finished run's (policy ``sb3:DIR``),
    cost per seed, and the run the zoo would ship (the lowest selected validation)."""

    rung: presets.Rung
    recipe: Recipe
    prior: str
    costs: dict[str, dict[int, float]]
    runs: list[Path]
    shipped: Path

    def gaps(self, policy: str) -> list[Gap]:
        """The gap ``policy`` closes on each test range."""
        return [gap_closed(_in_range(self.costs[policy], i), _in_range(self.costs[self.prior], i),
                           _in_range(self.costs[EXPERT], i)) for i in range(len(TEST_RANGES))]


def _in_range(costs: Mapping[int, float], index: int) -> dict[int, float]:
    return {s: c for s, c in costs.items() if range_of(s) == index}


class _Task(NamedTuple):
    spec: EpisodeSpec
    config_name: str


def evaluate_ladder(runs: Path, episodes: int = TEST_EPISODES, workers: int = 2, progress: bool = True) -> Ladder:
    """Every rung with a finished run: the prior, ``dv-mpc`` and the runs on the first ``episodes``
    seeds of each test range (:func:`evaluation.run.evaluate`)."""
    plans = []
    for rung, r in ladder_recipes():
        dirs = [Path(runs) / r.name / f"seed-{s}" for s in r.seeds]
        dirs = [d for d in dirs if finished(d, r.timesteps)]
        if dirs:
            plans.append((rung, r, anchor_name(resolve_interface(r.hp["interface"])), dirs))
    if not plans:
        raise ValueError(f"{runs}: no finished run of the ladder's recipes "
                         f"({', '.join(r.name for _, r in ladder_recipes())}; lawn zoo train --only NAME trains one)")
    specs, seeds = [], test_seeds(episodes)
    for rung, _, prior, dirs in plans:
        config = presets.get(rung.preset)
        specs += [_Task(EpisodeSpec(p, rung.env_id, config, s), rung.preset)
                  for p in (prior, EXPERT, *(f"sb3:{d}" for d in dirs)) for s in seeds]
    rows = [dataclasses.replace(row, task=spec.config_name) for spec, row in
            zip(specs, evaluate([s.spec for s in specs], workers=workers, progress=progress, desc="ladder"),
                strict=True)]
    out = []
    for rung, r, prior, dirs in plans:
        costs: dict[str, dict[int, float]] = {}
        for row in rows:
            if row.env == rung.env_id and row.task == rung.preset:
                costs.setdefault(row.policy, {})[row.seed] = row.control_cost
        shipped = min(dirs, key=run_key)
        out.append(RungResult(rung, r, prior, costs, dirs, shipped))
    return Ladder(out, rows)


@dataclass(frozen=True)
class Ladder:
    """The rungs' results and every episode played (their ``task`` is the rung's preset)."""

    rungs: list[RungResult]
    rows: list[EpisodeResult]


def render_ladder(ladder: Ladder) -> str:
    """The page's table: per rung, the prior's and the expert's cost, then each training seed's gap
    closed and its change against the prior on each test range (the zoo's run marked)."""
    first, second = (f"{base:,}.." for base in TEST_RANGES)
    head = ["rung (env): what is learned", "prior, cost", f"{EXPERT}, cost", "run (training seed)", "steps/s",
            f"gap closed, seeds {first}", f"gap closed, seeds {second}", f"vs prior, seeds {first}",
            f"vs prior, seeds {second}"]
    rows = []
    for res in ladder.rungs:
        rung = f"`{res.rung.preset}` ({res.rung.env_id.removeprefix('lawn/')}): {res.rung.learns}"
        for d in res.runs:
            policy = f"sb3:{d}"
            vs = [paired_geometric(_in_range(res.costs[policy], i), _in_range(res.costs[res.prior], i))
                  for i in range(len(TEST_RANGES))]
            mark = " (shipped)" if d == res.shipped and res.recipe.section == "scratch" else ""
            rows.append([rung, _mean_cost(res.costs[res.prior]), _mean_cost(res.costs[EXPERT]),
                         f"`{res.recipe.name}` seed {d.name.removeprefix('seed-')}{mark}", _rate(d),
                         *(g.cell() for g in res.gaps(policy)),
                         *(f"{100 * g.change:+.1f} % [{100 * (g.low - 1):+.1f}, {100 * (g.high - 1):+.1f}]"
                           for g in vs)])
            rung = ""
    episodes = len(next(iter(ladder.rungs[0].costs.values())))
    note = (f"{episodes} test seeds a row ({episodes // len(TEST_RANGES)} of each range), the validation-selected "
            f"model of each run; the prior is the zero action of the recipe's interface, the start of every run. "
            f"Gap closed: 100 x mean(log prior - log agent) / mean(log prior - log {EXPERT}) over the seeds, "
            "95 % bootstrap interval; vs prior: the geometric mean of the per-seed cost ratios.")
    return markdown_table(head, rows) + "\n\n" + note


def _mean_cost(costs: Mapping[int, float]) -> str:
    """The geometric mean cost over the seeds."""
    return f"{math.exp(np.mean(np.log(list(costs.values())))):,.1f}"


def _rate(run_dir: Path) -> str:
    """The run's steps per second of wall time (its record)."""
    rate = read_run(run_dir).record.steps_per_s
    return f"{rate:,.0f}" if rate else "–"


def plot_ladder(ladder: Ladder, path: Path) -> None:
    """One panel per rung: each run's validation change against its start (the prior) with its 95 %
    interval over training steps (the measure its selection read: the paired mean, or the geometric mean
    of the cost ratios), and the expert's change against the prior on the first test range."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    n = len(ladder.rungs)
    fig = Figure(figsize=(3.6 * n, 3.4), dpi=110)
    FigureCanvasAgg(fig)
    for j, res in enumerate(ladder.rungs):
        ax = fig.add_subplot(1, n, j + 1)
        for d in res.runs:
            rows = [r for r in read_learning_curve(d) if "vs_start" in r]
            t = np.array([r["timesteps"] for r in rows]) / 1e6
            geometric = selection_of(d) == "geometric" and all("vs_start_geometric_high" in r for r in rows)
            key = "vs_start_geometric" if geometric else "vs_start"
            m = 100 * np.array([r[key] for r in rows])
            lo, hi = ((100 * np.nan_to_num(np.array([r[f"{key}_{b}"] for r in rows]), nan=0.0) for b in ("low", "high"))
                      if geometric else (m - 100 * np.nan_to_num(np.array([r["vs_start_ci95"] for r in rows])),
                                         m + 100 * np.nan_to_num(np.array([r["vs_start_ci95"] for r in rows]))))
            ax.plot(t, m, "-o", ms=2, label=f"{d.name}{' (geometric)' if geometric else ''}")
            ax.fill_between(t, lo, hi, alpha=0.15)
        expert = paired_geometric(_in_range(res.costs[EXPERT], 0), _in_range(res.costs[res.prior], 0))
        ax.axhline(100 * expert.change, color="k", ls="--", lw=1, label=f"{EXPERT} (test seeds)")
        ax.axhline(0.0, color="0.5", lw=0.8)
        ax.set_title(f"{res.rung.preset} ({res.rung.env_id.removeprefix('lawn/')})", fontsize=9)
        ax.set_xlabel("environment steps (millions)", fontsize=8)
        if j == 0:
            ax.set_ylabel("validation cost vs the prior (%)\n(paired, 95 % CI)", fontsize=8)
        ax.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(path)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", required=True, help="the recipes' run directory (lawn zoo train --runs)")
    parser.add_argument("--out", required=True, help="where ladder.md, ladder.csv and ladder.png go")
    parser.add_argument("--episodes", type=int, default=TEST_EPISODES, help="test seeds of each range")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--quiet", action="store_true")
    parser.add_argument("--overwrite", action="store_true", help="replace the files of an earlier run in --out")
    args = parser.parse_args(argv)
    if args.episodes < 3:
        parser.error(f"--episodes {args.episodes}: at least 3 (the bootstrap interval)")
    there = [name for name in OUTPUTS if (Path(args.out) / name).exists()]
    if there and not args.overwrite:
        parser.error(f"--out {args.out} already holds {', '.join(there)}; pass --overwrite to replace them")
    ladder = evaluate_ladder(Path(args.runs), args.episodes, args.workers, not args.quiet)
    table = render_ladder(ladder)  # everything is computed before the first file is written
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_results(ladder.rows, out / "ladder.csv", atomic=True)
    plot_ladder(ladder, out / "ladder.png")
    (out / "ladder.md").write_text(table + "\n")
    print(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
