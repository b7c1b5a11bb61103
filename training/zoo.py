"""The shipped learned agents: how each is trained, how it compares, what is exported.

:data:`RECIPES` is the one list of learned comparators. ``lawn zoo train`` trains every recipe
for each of its training seeds into ``RUNS/<name>/seed-<s>`` (a process pool; finished runs are
kept); ``lawn zoo build`` evaluates every run on the benchmark's test seeds (full 120-slot
episodes of the unmodified scenario, realized control cost, paired with ``rg-mpc`` on the same
seeds), exports the run selected on the validation seeds as ``agents/zoo/<name>`` (policy
weights and observation statistics only) and writes the learned-agents table into
``docs/LEARNED.md`` and the README. ``lawn zoo list`` shows the shipped agents.
``scripts/train_agents.sh`` runs both steps.
"""

from __future__ import annotations

import json
import math
import shlex
import shutil
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from agents.learned import ZOO_DIR, export_agent, zoo_agents
from agents.runs import read_run
from lawn_env import ScenarioConfig

from .bc import VALIDATION_EPISODES as BC_VALIDATION_EPISODES
from .evaluate import evaluate, pool_map, write_rows
from .protocol import VALIDATION_SEED_BASE, read_learning_curve
from .tables import mean_ci
from .train import train_task

__all__ = ["Recipe", "RECIPES", "train_recipes", "build_zoo", "format_zoo_list"]

TEST_EPISODES = 20


@dataclass(frozen=True)
class Recipe:
    """One learned comparator: ``lawn train`` arguments, its training seeds and its table label."""

    name: str
    label: str
    algo: str
    env_id: str
    timesteps: int
    seeds: tuple[int, ...] = (0, 1, 2)
    hp: dict = field(default_factory=dict)
    init_from: str | None = None  # another recipe's name: seed s starts from that recipe's seed s
    eval_every: int = 25_000
    vec: str = "dummy"  # lawn train --vec: "native" trains on lawn's batched vector env

    @property
    def evaluated_on(self) -> str:
        return "lawn/Joint-v0" if self.env_id == "lawn/Parallel-v0" else self.env_id

    def command(self) -> str:
        parts = [f"lawn train --algo {self.algo} --env {self.env_id} --timesteps {self.timesteps}",
                 f"--seeds {' '.join(map(str, self.seeds))}", f"--out RUNS/{self.name}"]
        parts += [f"--hp {shlex.quote(f'{k}={json.dumps(v)}')}" for k, v in self.hp.items()]
        if self.vec != "dummy":
            parts.append(f"--vec {self.vec}")
        if self.init_from:
            parts.append(f"--init-from RUNS/{self.init_from}/seed-<s>")
        return " ".join(parts)


_DAGGER = {"dagger_iterations": 4, "dagger_timesteps": 4800}
_FINE_TUNE = {"learning_rate": "lin_5e-5", "clip_range": 0.1, "init_log_std": -2.5, "actor_warmup_steps": 10_000}

#: The learned comparators, in training order (a recipe that starts from another comes after it).
RECIPES: tuple[Recipe, ...] = (
    Recipe("ppo-comm", "PPO (RL interface)", "ppo", "lawn/Comm-v0", 300_000, eval_every=50_000, vec="native"),
    Recipe("ppo-joint", "PPO (RL interface, residual on the MPC)", "ppo", "lawn/Joint-v0", 300_000, eval_every=50_000,
           vec="native"),
    Recipe("ppo-marl", "PPO multi-agent, shared weights", "ppo", "lawn/Parallel-v0", 150_000, eval_every=25_000),
    Recipe("sac-comm", "SAC (RL interface)", "sac", "lawn/Comm-v0", 20_000, eval_every=5_000),
    Recipe("bc-comm", "BC of rg-mpc (+4 DAgger rounds)", "bc", "lawn/Comm-v0", 12_000, hp=_DAGGER),
    Recipe("ppo-comm-from-bc", "BC then PPO fine-tuning", "ppo", "lawn/Comm-v0", 60_000, init_from="bc-comm",
           hp=_FINE_TUNE, eval_every=10_000),
    Recipe("bc-joint", "BC of rg-mpc (+4 DAgger rounds)", "bc", "lawn/Joint-v0", 12_000, hp=_DAGGER),
    Recipe("ppo-joint-from-bc", "BC then PPO fine-tuning", "ppo", "lawn/Joint-v0", 60_000, init_from="bc-joint",
           hp=_FINE_TUNE, eval_every=10_000),
)


def _recipe(name: str) -> Recipe:
    for r in RECIPES:
        if r.name == name:
            return r
    raise ValueError(f"unknown recipe {name!r}; valid: {', '.join(r.name for r in RECIPES)}")


def _finished(run_dir: Path, timesteps: int) -> bool:
    if not (run_dir / "run.json").exists():
        return False
    data = read_run(run_dir).record
    return int(data.get("num_timesteps", 0)) >= (timesteps if data.get("trainer") != "bc" else 1)


def train_recipes(runs: Path, names: list[str] | None = None, workers: int = 2, progress: bool = True) -> list[Path]:
    """Train the missing runs of the chosen recipes (all by default); returns the run directories.
    Runs that start from another recipe wait for it (two phases)."""
    runs = Path(runs)
    chosen = [_recipe(n) for n in names] if names else list(RECIPES)
    done: list[Path] = []
    for phase in (False, True):
        tasks = []
        for r in chosen:
            if bool(r.init_from) != phase:
                continue
            for s in r.seeds:
                out = runs / r.name / f"seed-{s}"
                done.append(out)
                if _finished(out, r.timesteps):
                    continue
                if out.exists():
                    shutil.rmtree(out)  # an unfinished run: start it again from scratch
                tasks.append(dict(algo=r.algo, env_id=r.env_id, config=ScenarioConfig(), timesteps=r.timesteps, seed=s,
                                  out_dir=out, hp_overrides=dict(r.hp), eval_every=r.eval_every, eval_episodes=10,
                                  progress=False, vec=r.vec,
                                  init_from=runs / r.init_from / f"seed-{s}" if r.init_from else None))
        pool_map(train_task, tasks, workers, progress, desc="training runs")
    return done


def build_zoo(runs: Path, out_doc: Path, readme: Path | None, workers: int = 2, progress: bool = True,
              episodes: int = TEST_EPISODES, export: bool = True) -> str:
    """Evaluate every finished recipe run on the test seeds 0..episodes-1 beside rg-mpc and epa,
    export the validation-selected seed of each recipe, write the table; returns it (Markdown)."""
    runs = Path(runs)
    cfg = ScenarioConfig()
    found = [(r, [runs / r.name / f"seed-{s}" for s in r.seeds if _finished(runs / r.name / f"seed-{s}", r.timesteps)])
             for r in RECIPES]
    found = [(r, dirs) for r, dirs in found if dirs]
    if not found:
        raise ValueError(f"{runs}: no finished recipe runs (lawn zoo train --runs {runs} trains them)")
    envs = sorted({r.evaluated_on for r, _ in found})
    tasks = [(name, env, cfg, i, {}) for env in envs for name in ("rg-mpc", "epa") for i in range(episodes)]
    run = {d: read_run(d) for _, dirs in found for d in dirs}
    tasks += [(run[d].policy_name, r.evaluated_on, cfg, i, {})
              for r, dirs in found for d in dirs for i in range(episodes)]
    rows = evaluate(tasks, workers=workers, progress=progress, desc="zoo benchmark")
    write_rows(rows, out_doc.parent / "learned" / "episodes.csv")
    cost = {(r["policy"], r["env"], int(r["seed"])): float(r["control_cost"]) for r in rows}

    def paired(policy: str, env: str) -> np.ndarray:
        return np.array([cost[(policy, env, i)] / cost[("rg-mpc", env, i)] - 1.0 for i in range(episodes)])

    lines = ["| agent | env (evaluated on) | algorithm, interface | budget per run | training seeds | wall time per run "
             "| control cost (mean over seeds) | vs rg-mpc, mean over training seeds | shipped seed vs rg-mpc (paired, 20 test seeds) |",
             "|" + "---|" * 9]
    per_run = ["| recipe | training seed | power prior | best validation cost (episodes) | vs rg-mpc (paired, test seeds) "
               "| worst test seed vs rg-mpc | wall time |", "|" + "---|" * 7]
    for env in envs:
        for name in ("rg-mpc", "epa"):
            c = mean_ci(cost[(name, env, i)] for i in range(episodes))
            d = mean_ci(paired(name, env))
            vs = "–" if name == "rg-mpc" else f"{_pct(d[0])} ± {_pct(d[1], sign=False)}"
            lines.append(f"| {name} | {env} | expert | – | – | – | {_num(c[0])} ± {_num(c[1])} | {vs} | {vs} |")
        for r, dirs in found:
            if r.evaluated_on != env:
                continue
            specs = [run[d].record for d in dirs]
            per_seed = [paired(run[d].policy_name, env).mean() for d in dirs]
            costs = [np.mean([cost[(run[d].policy_name, env, i)] for i in range(episodes)]) for d in dirs]
            across, across_ci = mean_ci(per_seed)
            validation = [_best_validation(d) for d in dirs]
            chosen = dirs[int(np.argmin(validation))]
            for d, spec, best in zip(dirs, specs, validation):
                diff = paired(run[d].policy_name, env)
                mean, half = mean_ci(diff)
                prior = (spec.get("interface") or {}).get("power_anchor", "distance")
                shown = spec.get("eval_episodes", BC_VALIDATION_EPISODES)  # BC runs before it was recorded
                per_run.append(f"| `{r.name}`{' (shipped)' if d == chosen else ''} | {spec['seed']} | {prior} "
                               f"| {_num(best)} ({shown}) | {_pct(mean)} ± {_pct(half, sign=False)} | {_pct(float(diff.max()))} "
                               f"| {spec['wall_time_s']:.0f} s |")
            ship = mean_ci(paired(run[chosen].policy_name, env))
            wall = np.mean([s["wall_time_s"] for s in specs])
            steps = int(specs[0].get("num_timesteps", r.timesteps))
            iface = specs[0].get("interface") or {}
            scheme = "v0" if iface.get("action_scheme", "direct") == "direct" else "RL interface"
            lines.append(
                f"| {r.label} (`zoo:{r.name}`) | {env} | {r.algo.upper() if r.algo != 'bc' else 'BC→PPO net'}, {scheme} "
                f"| {steps:,} steps | {len(dirs)} | {wall:.0f} s | {_num(float(np.mean(costs)))} "
                f"| {_pct(across)}{'' if math.isnan(across_ci) else ' ± ' + _pct(across_ci, sign=False)} "
                f"| {_pct(ship[0])} ± {_pct(ship[1], sign=False)} (seed {run[chosen].record['seed']}) |")
            if export:
                _export(r, chosen, dirs, specs, ship, across, across_ci, env)
    sources = sorted({rd.record.get("versions", {}).get("source", "not recorded") for rd in run.values()})
    lines += ["", "Training runs made at: " + "; ".join(sources) + (
        " (runs from before commits were recorded were trained on the scenario of their day; their learning "
        "curves are in that scenario, every cost in this table is measured now)" if "not recorded" in sources else "")
        + "."]
    table = "\n".join(lines)
    out_doc.parent.mkdir(parents=True, exist_ok=True)
    reference = {env: evaluate([("rg-mpc", env, cfg, VALIDATION_SEED_BASE + i, {}) for i in range(10)], workers=workers,
                               progress=False) for env in envs}
    _plot_curves(found, {env: float(np.mean([r["control_cost"] for r in rs])) for env, rs in reference.items()},
                 out_doc.parent / "learned" / "curves.png")
    out_doc.write_text(_document(table, "\n".join(per_run), episodes))
    if readme is not None:
        _replace_block(readme, table)
    return table


def _plot_curves(found, reference: dict[str, float], path: Path) -> None:
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


def _best_validation(run_dir: Path) -> float:
    return min((r["control_cost"] for r in read_learning_curve(run_dir)), default=math.inf)


def _export(r: Recipe, chosen: Path, dirs, specs, ship, across, across_ci, env) -> None:
    record = {
        "name": r.name, "label": r.label, "trained_on": r.env_id, "evaluated_on": env,
        "command": r.command(), "budget_steps": int(specs[0].get("num_timesteps", r.timesteps)),
        "training_seeds": [s["seed"] for s in specs], "shipped_seed": read_run(chosen).record["seed"],
        "selected_on": "lowest mean control cost on the validation seeds (500000 + i), never the test seeds",
        "wall_time_s": [round(s["wall_time_s"], 1) for s in specs],
        "benchmark": {"test_seeds": f"0-{TEST_EPISODES - 1}", "reference": "rg-mpc",
                      "shipped_vs_reference": [ship[0], ship[1]],
                      "across_training_seeds_vs_reference": [across, across_ci]},
    }
    target = ZOO_DIR / r.name
    if target.exists():
        shutil.rmtree(target)
    export_agent(chosen, target, record)


def _document(table: str, per_run: str, episodes: int) -> str:
    from .provenance import provenance

    return f"""# Learned comparators

Generated by `lawn zoo build` (`scripts/train_agents.sh` trains and builds) at {provenance()}. Every number is the
realized control cost of full 120-slot episodes of the unmodified scenario (`lawn/Comm-v0` or
`lawn/Joint-v0`, default config) on the test seeds 0-{episodes - 1}, whatever interface the agent
was trained with. Model selection (the best checkpoint of a run, the shipped seed of a recipe)
uses only the validation seeds 500000+i; training episodes use seeds 1000000 + 1000 s + ....
"vs rg-mpc" is the per-test-seed relative difference in control cost against `rg-mpc` on the
same seed, averaged over the test seeds; "mean over training seeds" averages that per training
run and gives a 95 % t-interval across training seeds; the last column is the paired 95 %
interval of the shipped run over the test seeds.

{table}

Every training run (the power prior is the anchored power split the run trained and acts with,
`lawn_env.interface`; the best validation cost is the selected checkpoint's, on the first
validation seeds; the worst test seed is the largest per-seed relative difference against `rg-mpc`):

{per_run}

Validation cost during training (every seed of every recipe; dashed: `rg-mpc` on the same
validation seeds):

![learning curves](learned/curves.png)
"""


def _replace_block(readme: Path, table: str) -> None:
    from .readme import replace_block

    replace_block(readme, "learned-agents", table, source="lawn zoo build")


def _pct(x: float, sign: bool = True) -> str:
    if not math.isfinite(x):
        return "n/a"
    return f"{x * 100:+.1f} %" if sign else f"{x * 100:.1f} %"


def _num(x: float) -> str:
    if not math.isfinite(x):
        return "n/a"
    return f"{x:,.0f}" if abs(x) < 1e5 else f"{x:.3g}"


def format_zoo_list() -> str:
    agents = zoo_agents()
    if not agents:
        return "no shipped agents (lawn zoo build exports them)"
    lines = []
    for name, rec in agents.items():
        bench = rec.get("benchmark", {})
        ship = bench.get("shipped_vs_reference", [math.nan, math.nan])
        lines.append(f"zoo:{name}  {rec.get('label', '')}")
        lines.append(f"  drives {rec.get('evaluated_on')} (trained on {rec.get('trained_on')}, {rec.get('algo')}), "
                     f"{rec.get('budget_steps', 0):,} steps, training seeds {rec.get('training_seeds')}, shipped seed "
                     f"{rec.get('shipped_seed')}")
        lines.append(f"  test seeds {bench.get('test_seeds')}: cost vs rg-mpc {_pct(ship[0])} ± {_pct(ship[1], sign=False)}")
        lines.append(f"  trained with: {rec.get('command')}")
    return "\n".join(lines)
