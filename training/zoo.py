"""The shipped learned agents: how each is trained, how it compares, what is exported.

:data:`RECIPES` is the one list of learned comparators. ``lawn zoo train`` trains every recipe
for each of its training seeds into ``RUNS/<name>/seed-<s>`` (a process pool; finished runs are
kept); ``lawn zoo build`` evaluates every run by the learned protocol (:mod:`training.leaderboard`:
full 120-slot episodes of the unmodified scenario on 100 test seeds, realized control cost,
paired with ``rg-mpc`` and with the agent's own anchor on the same seeds, normalized score), exports the run selected on the validation seeds as ``agents/zoo/<name>`` (policy
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
from lawn_env import PARALLEL_ENV_ID, ScenarioConfig, central_env_id

from .evaluate import evaluate, pool_map, write_rows
from .leaderboard import learned_entries, own_anchor, paired, protocol_cells, run_entries
from .protocol import TEST_EPISODES, VALIDATION_SEED_BASE, read_learning_curve, selected_validation, selection_key
from .score import SCORE_HIGH, SCORE_VERSION, scores_by_policy
from .tables import fmt_num, fmt_paired, fmt_pct, mean_ci
from .train import train_task

__all__ = ["Recipe", "RECIPES", "train_recipes", "build_zoo", "format_zoo_list"]



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
        return central_env_id(self.env_id)

    def command(self) -> str:
        parts = [f"lawn train --algo {self.algo} --env {self.env_id} --timesteps {self.timesteps}",
                 f"--seeds {' '.join(map(str, self.seeds))}", f"--out RUNS/{self.name}"]
        parts += [f"--hp {shlex.quote(f'{k}={json.dumps(v)}')}" for k, v in self.hp.items()]
        if self.vec != "dummy":
            parts.append(f"--vec {self.vec}")
        if self.init_from:
            parts.append(f"--init-from RUNS/{self.init_from}/seed-<s>")
        return " ".join(parts)


#: Validation episodes of every zoo run (model selection; the test seeds are never used).
ZOO_VALIDATION_EPISODES = 20
#: Imitation at scale: 100,000 labels of rg-mpc, then 4 DAgger rounds of 10,000 on the clone's own
#: states, a 256 x 256 network (issue #24: at 12,000 + 4 x 4,800 labels and 128 x 128 the clone was
#: +2.8 % of rg-mpc on the test seeds; at this budget +0.1 %, 13-14 minutes a run two side by side).
_BC_AT_SCALE = {"dagger_iterations": 4, "dagger_timesteps": 10_000,
                "policy_kwargs": {"net_arch": [256, 256], "log_std_init": -1.0}}
_FINE_TUNE = {"learning_rate": "lin_5e-5", "clip_range": 0.1, "init_log_std": -2.5, "actor_warmup_steps": 10_000,
              "policy_kwargs": {"net_arch": [256, 256], "log_std_init": -1.0}}  # the clone's network
#: From scratch: the distance prior and the centroid drone (no MPC in the action; the Comm env's
#: own MPC still drives the AGVs), and the exploration and step size a learner far from the
#: optimum needs (log-std -1, 3e-4 decayed).
_SCRATCH = {"interface": {"base": "rl", "power_anchor": "distance"}, "learning_rate": "lin_3e-4",
            "policy_kwargs": {"net_arch": [128, 128], "log_std_init": -1.0}}

#: From scratch on Joint: the same, with the LQR baseline's increments under the residual.
_SCRATCH_JOINT = {**_SCRATCH, "interface": {**_SCRATCH["interface"], "increment_anchor": "lqr"}}

#: The learned comparators. Training runs them in this order, the longest first (a recipe that
#: starts from another runs in a second phase); the tables list them per env in this order.
RECIPES: tuple[Recipe, ...] = (
    Recipe("bc-comm", "BC of rg-mpc, 100k labels + 4 DAgger rounds", "bc", "lawn/Comm-v0", 100_000, hp=_BC_AT_SCALE),
    Recipe("bc-joint", "BC of rg-mpc, 100k labels + 4 DAgger rounds", "bc", "lawn/Joint-v0", 100_000,
           hp=_BC_AT_SCALE),
    Recipe("ppo-comm-scratch", "PPO from the distance prior (no MPC in the action)", "ppo", "lawn/Comm-v0",
           1_000_000, hp=_SCRATCH, eval_every=100_000, vec="native"),
    Recipe("ppo-joint-scratch", "PPO from the distance prior and the LQR (no MPC in the action)", "ppo",
           "lawn/Joint-v0", 1_000_000, hp=_SCRATCH_JOINT, eval_every=100_000, vec="native"),
    Recipe("ppo-comm", "PPO (RL interface)", "ppo", "lawn/Comm-v0", 300_000, eval_every=50_000, vec="native"),
    Recipe("ppo-joint", "PPO (RL interface, residual on the MPC)", "ppo", "lawn/Joint-v0", 300_000, eval_every=50_000,
           vec="native"),
    Recipe("sac-comm", "SAC (RL interface)", "sac", "lawn/Comm-v0", 20_000, eval_every=5_000),
    Recipe("ppo-marl", "PPO multi-agent, shared weights", "ppo", PARALLEL_ENV_ID, 150_000, eval_every=25_000),
    Recipe("ppo-comm-from-bc", "BC then PPO fine-tuning", "ppo", "lawn/Comm-v0", 60_000, init_from="bc-comm",
           hp=_FINE_TUNE, eval_every=10_000),
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
                                  out_dir=out, hp_overrides=dict(r.hp), eval_every=r.eval_every,
                                  eval_episodes=ZOO_VALIDATION_EPISODES,
                                  progress=False, vec=r.vec,
                                  init_from=runs / r.init_from / f"seed-{s}" if r.init_from else None))
        pool_map(train_task, tasks, workers, progress, desc="training runs")
    return done


def build_zoo(runs: Path, out_doc: Path, readme: Path | None, workers: int = 2, progress: bool = True,
              episodes: int = TEST_EPISODES, export: bool = True) -> str:
    """Evaluate every finished recipe run by the learned protocol (:mod:`training.leaderboard`: test
    seeds 0..episodes-1 beside rg-mpc, epa and each agent's own anchor), export the
    validation-selected seed of each recipe, write the tables; returns the recipe table (Markdown)."""
    runs = Path(runs)
    found = [(r, [runs / r.name / f"seed-{s}" for s in r.seeds if _finished(runs / r.name / f"seed-{s}", r.timesteps)])
             for r in RECIPES]
    found = [(r, dirs) for r, dirs in found if dirs]
    if not found:
        raise ValueError(f"{runs}: no finished recipe runs (lawn zoo train --runs {runs} trains them)")
    run = {d: read_run(d) for _, dirs in found for d in dirs}
    entries = learned_entries([run[d].policy_name for _, dirs in found for d in dirs])
    rows = run_entries(entries, ScenarioConfig(), range(episodes), workers, progress, desc="zoo benchmark")
    write_rows(rows, out_doc.parent / "learned" / "episodes.csv")
    scores = scores_by_policy(rows)
    envs = list(dict.fromkeys(env for _, env in entries))
    table = [f"| agent | env | algorithm, budget per run | acts around | control cost | score v{SCORE_VERSION} [95 %] "
             "| vs rg-mpc (paired) | vs own anchor (paired) | vs own anchor, mean over training seeds |", "|" + "---|" * 9]
    per_run = [f"| recipe | training seed | acts around | selected validation: vs rg-mpc (cost, episodes) "
               f"| score v{SCORE_VERSION} "
               "| vs rg-mpc (paired) | vs own anchor (paired) | worst test seed vs own anchor | wall time |",
               "|" + "---|" * 9]
    for env in envs:
        for policy, _ in [e for e in entries if e[1] == env and not e[0].startswith(("sb3:", "bc:", "marl:"))]:
            table.append(_row(rows, scores, policy, env, policy, "expert" if ":" not in policy else "zero action", "–"))
        for r, dirs in found:
            if r.evaluated_on != env:
                continue
            validation = [_best_validation(d) for d in dirs]
            chosen = dirs[int(np.argmin([selection_key(v) for v in validation]))]
            gains = [paired(rows, run[d].policy_name, own_anchor(run[d].policy_name), env) for d in dirs]
            across = mean_ci(g[0] for g in gains)
            for d, best in zip(dirs, validation):
                spec = run[d].record
                c = protocol_cells(rows, scores, run[d].policy_name, env)
                per_run.append(f"| `{r.name}`{' (shipped)' if d == chosen else ''} | {spec['seed']} | {c['anchor']} "
                               f"| {_validation_cell(best, spec.get('eval_episodes', '?'))} | {c['score']} "
                               f"| {c['vs_ref']} | {c['vs_anchor']} | {c['worst']} | {spec['wall_time_s']:.0f} s |")
            specs = [run[d].record for d in dirs]
            algo = r.algo.upper() if r.algo != "bc" else "BC"
            budget = f"{algo}, {int(specs[0].get('num_timesteps', r.timesteps)):,} steps, {np.mean([s['wall_time_s'] for s in specs]):.0f} s"
            table.append(_row(rows, scores, run[chosen].policy_name, env,
                              f"{r.label} (`zoo:{r.name}`, seed {run[chosen].record['seed']})", budget,
                              f"{fmt_paired(*across)} ({len(dirs)} seeds)"))
            if export:
                _export(r, chosen, specs, rows, scores, env, episodes, across)
    sources = sorted({rd.record.get("versions", {}).get("source", "not recorded") for rd in run.values()})
    floor = [f"`{a}` on {env} {fmt_paired(*paired(rows, SCORE_HIGH, a, env))}" for a, env in entries
             if a.startswith("anchor:")]
    text = "\n".join(table) + (f"\n\n{episodes} test seeds (0-{episodes - 1}); training runs made at: "
                               + "; ".join(sources) + ". `rg-mpc` itself against each anchor (the \"vs own "
                               "anchor\" of a perfect clone of the expert): " + "; ".join(floor) + ".")
    out_doc.parent.mkdir(parents=True, exist_ok=True)
    reference = {env: evaluate([("rg-mpc", env, ScenarioConfig(), VALIDATION_SEED_BASE + i, {}) for i in range(10)],
                               workers=workers, progress=False) for env in envs}
    _plot_curves(found, {env: float(np.mean([r["control_cost"] for r in rs])) for env, rs in reference.items()},
                 out_doc.parent / "learned" / "curves.png")
    out_doc.write_text(_document(text, "\n".join(per_run), episodes))
    if readme is not None:
        _replace_block(readme, text)
    return text


def _row(rows, scores, policy: str, env: str, label: str, how: str, across: str) -> str:
    """One row of the recipe table: an expert, an anchor or a recipe's shipped run."""
    c = protocol_cells(rows, scores, policy, env)
    return (f"| {label} | {env} | {how} | {c['anchor']} | {c['cost']} | {c['score']} | {c['vs_ref']} "
            f"| {c['vs_anchor']} | {across} |")


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


def _best_validation(run_dir: Path) -> dict[str, float]:
    """The run's selected validation (:func:`~training.protocol.selected_validation`)."""
    return selected_validation(read_learning_curve(run_dir)) or {"control_cost": math.inf}


def _validation_cell(best: dict[str, float], episodes: int) -> str:
    vs = fmt_pct(best["vs_reference"]) if "vs_reference" in best else "–"
    return f"{vs} ({fmt_num(best['control_cost'])}, {episodes})"


def _export(r: Recipe, chosen: Path, specs, rows, scores, env: str, episodes: int, across) -> None:
    policy = read_run(chosen).policy_name
    anchor = own_anchor(policy)
    record = {
        "name": r.name, "label": r.label, "trained_on": r.env_id, "evaluated_on": env,
        "command": r.command(), "budget_steps": int(specs[0].get("num_timesteps", r.timesteps)),
        "training_seeds": [s["seed"] for s in specs], "shipped_seed": read_run(chosen).record["seed"],
        "selected_on": "lowest paired relative difference against rg-mpc on the validation seeds (500000 + i), "
                       "never the test seeds",
        "wall_time_s": [round(s["wall_time_s"], 1) for s in specs],
        "benchmark": {"test_seeds": f"0-{episodes - 1}", "reference": SCORE_HIGH, "anchor": anchor,
                      "score_version": SCORE_VERSION, "score": list(scores[("default", env, policy)][:3]),
                      "shipped_vs_reference": list(paired(rows, policy, SCORE_HIGH, env)),
                      "shipped_vs_anchor": list(paired(rows, policy, anchor, env)),
                      "across_training_seeds_vs_anchor": list(across)},
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
was trained with (the learned protocol, `training/leaderboard.py`). Model selection (the best
checkpoint of a run among its start and the checkpoints significantly better than the start, the
shipped seed of a recipe) uses only the validation seeds 500000+i; training episodes use seeds
1000000 + 1000 s + ....

Each agent acts around the zero action of its interface ("acts around": `anchor:stake` or
`anchor:distance`, `agents/anchors.py`), which is a row of its own on the same seeds; "vs own
anchor" is the per-test-seed relative difference in control cost against it, averaged over the
test seeds with a paired 95 % t-interval: what learning adds. "vs rg-mpc" is the same against the
expert. The score is the normalized score v1 (`training/score.py`: 0 = `epa`, 100 = `rg-mpc`,
95 % paired bootstrap interval). The last column averages "vs own anchor" per training run and
gives a 95 % t-interval across the training seeds.

{table}

Every training run (the selected validation is the checkpoint with the lowest mean per-seed
relative difference against `rg-mpc` on the validation seeds, paired on the same seeds; the
shipped seed of a recipe is the run whose selected validation is lowest; the worst test seed is
the largest per-seed relative difference against the run's own anchor):

{per_run}

Validation cost during training (every seed of every recipe; dashed: `rg-mpc` on the same
validation seeds):

![learning curves](learned/curves.png)
"""


def _replace_block(readme: Path, table: str) -> None:
    from .readme import replace_block

    replace_block(readme, "learned-agents", table, source="lawn zoo build")


def format_zoo_list() -> str:
    agents = zoo_agents()
    if not agents:
        return "no shipped agents (lawn zoo build exports them)"
    lines = []
    for name, rec in agents.items():
        bench = rec.get("benchmark", {})
        ship = bench.get("shipped_vs_reference", [math.nan, math.nan])
        gain = bench.get("shipped_vs_anchor", [math.nan, math.nan])
        lines.append(f"zoo:{name}  {rec.get('label', '')}")
        lines.append(f"  drives {rec.get('evaluated_on')} (trained on {rec.get('trained_on')}, {rec.get('algo')}), "
                     f"{rec.get('budget_steps', 0):,} steps, training seeds {rec.get('training_seeds')}, shipped seed "
                     f"{rec.get('shipped_seed')}")
        lines.append(f"  test seeds {bench.get('test_seeds')}: cost vs rg-mpc {fmt_paired(*ship)}, vs its anchor "
                     f"{bench.get('anchor', '?')} {fmt_paired(*gain)}, score v{bench.get('score_version', '?')} "
                     f"{bench.get('score', [math.nan])[0]:.1f}")
        lines.append(f"  trained with: {rec.get('command')}")
    return "\n".join(lines)
