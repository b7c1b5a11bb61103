"""The task suite (``lawn benchmark --suite``, docs/LEADERBOARD.md): the presets of
:data:`lawn_env.presets.SUITE`, every expert, baseline, shipped agent, the stake and distance
anchors and the reference rows (:mod:`training.limits`) on each, scored against the references of
the same task and env (:mod:`training.score`), with the IQM over tasks, each task's cost structure,
noise floor and headroom, every row per task and a figure of the mean cost per slot. Agents trained
on the default task are run on every task; where one cannot act (its network was built for K = 4)
the table says so.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Mapping, Sequence

from agents.base import JOINT
from agents.errors import MissingExtra
from agents.learned import zoo_agents
from lawn_env import ScenarioConfig, presets

from .evaluate import TRANSIENT_SLOTS, build_policy, write_rows
from .leaderboard import costs_of, geometric, mean_cell, policy_env, run_entries
from .limits import REFERENCE_ROWS, is_reference_row
from .score import SCORE_HIGH, SCORE_LOW, SCORE_VERSION, aggregate_score, format_score, score_inputs, scores_by_policy
from .tables import fmt_geometric, fmt_num, fmt_paired, fmt_pct, mean_ci, paired_difference

__all__ = ["SUITE_POLICIES", "suite_policies", "run_suite", "suite_table", "structure_table", "task_tables",
           "plot_profiles", "skipped_summary", "write_leaderboard"]

#: Experts and baselines of the suite (global-mpc, seconds per slot, is the gap study's reference).
SUITE_POLICIES = ("dv-mpc", "rg-mpc", "ao-mpc", "epa", "sf", "pid", "lqr", "heuristic", "anchor:stake", "anchor:distance")


def suite_policies() -> list[str]:
    """The experts, baselines and anchors of :data:`SUITE_POLICIES` (``anchor:hover`` left out: its
    cost is thousands of times the experts') and every shipped agent."""
    return list(SUITE_POLICIES) + [f"zoo:{n}" for n in zoo_agents()]


def _applicable(policy: str, env: str, config: ScenarioConfig) -> str | None:
    """None when ``policy`` can act on ``env`` with ``config``, else why not (one line). Names are
    checked on the default task first (by the caller), so a typo is an error, not an n/a."""
    try:
        build_policy(policy, config, env)
    except (ValueError, MissingExtra) as exc:  # a network built for another K; torch not installed
        return str(exc)
    return None


def run_suite(policies: Sequence[str], tasks: Sequence[str], episodes: int, out_dir: Path, workers: int = 1,
              progress: bool = True, transient_slots: int = TRANSIENT_SLOTS
              ) -> tuple[list[dict], dict[tuple[str, str], str], float]:
    """Every policy on every task (seeds 0..episodes-1), with the references of each env used and
    the reference rows (:data:`training.limits.REFERENCE_ROWS`: the noise floor and the two
    headroom rows, on ``lawn/Joint-v0``); writes ``episodes.csv`` and ``per_slot.csv`` (the mean
    stage cost per slot of every task, env and policy). Returns the rows, the (task, policy) pairs
    that cannot run with the reason, and the wall time."""
    start = time.perf_counter()
    policies = list(dict.fromkeys(policies))
    envs = {p: policy_env(p) for p in policies}
    for p in policies:  # unknown names and agents that cannot act on the default task are errors
        build_policy(p, ScenarioConfig(), envs[p])
    rows: list[dict] = []
    profiles: list[dict] = []
    skipped: dict[tuple[str, str], str] = {}
    for task in tasks:
        config = presets.get(task)
        entries = [(p, env) for env in dict.fromkeys([JOINT, *envs.values()]) for p in (SCORE_HIGH, SCORE_LOW)]
        entries += [(p, JOINT) for p in REFERENCE_ROWS]
        for p in policies:
            reason = _applicable(p, envs[p], config)
            if reason is not None:
                skipped[(task, p)] = reason
            elif (p, envs[p]) not in entries:
                entries.append((p, envs[p]))
        rows += run_entries(entries, config, range(episodes), workers, progress, task=task, desc=f"suite: {task}",
                            transient_slots=transient_slots, profiles=profiles)
    write_rows(rows, Path(out_dir) / "episodes.csv")
    write_rows(profiles, Path(out_dir) / "per_slot.csv")
    return rows, skipped, time.perf_counter() - start


def _aggregate(rows: Sequence[Mapping], env: str, policy: str, tasks: Sequence[str], inputs: Mapping
               ) -> tuple[float, float, float, int]:
    """The IQM over ``tasks`` of ``policy``'s scores on ``env`` (:func:`training.score.aggregate_score`)."""
    return aggregate_score({t: inputs[(t, env, policy)] for t in tasks if (t, env, policy) in inputs})


def suite_table(rows: Sequence[Mapping], policies: Sequence[str], tasks: Sequence[str],
                skipped: Mapping[tuple[str, str], str]) -> tuple[str, str]:
    """The leaderboard (score per task, the IQM over tasks with its stratified bootstrap interval)
    and the references' costs per task."""
    scores, inputs = scores_by_policy(rows), score_inputs(rows)
    at = list(policies).index(SCORE_HIGH) + 1 if SCORE_HIGH in policies else 0  # the reference rows after the expert
    names = list(dict.fromkeys([*policies[:at], *REFERENCE_ROWS, *policies[at:]]))
    lines = ["| policy | env | " + " | ".join(tasks) + " | IQM over tasks [95 %] |", "|" + "---|" * (len(tasks) + 3)]
    for p in names:
        env = JOINT if is_reference_row(p) else policy_env(p)
        if is_reference_row(p) and not any(r["policy"] == p for r in rows):
            continue
        cells = []
        for task in tasks:
            score = scores.get((task, env, p))
            cells.append("n/a" if (task, p) in skipped else format_score(score))
        iqm, lo, hi, n = _aggregate(rows, env, p, tasks, inputs)
        overall = "–" if n == 0 else format_score((iqm, lo, hi, n)) + ("" if n == len(tasks) else f" ({n} task{'s' * (n != 1)})")
        lines.append(f"| {p} | {env} | " + " | ".join(cells) + f" | {overall} |")
    refs = [f"| task | env | episodes | {SCORE_LOW} cost | {SCORE_HIGH} cost | gap (mean) | per-seed gap / {SCORE_HIGH} cost, "
            f"min to max | seeds where {SCORE_LOW} costs no more |", "|" + "---|" * 8]
    for task in tasks:
        for env in dict.fromkeys(r["env"] for r in rows if r.get("task") == task):
            low, high = costs_of(rows, SCORE_LOW, env, task), costs_of(rows, SCORE_HIGH, env, task)
            if not low or not high:
                continue
            lo, hi = mean_ci(low.values()), mean_ci(high.values())
            gap = lo[0] - hi[0]
            per_seed = [(low[s] - high[s]) / high[s] for s in low if s in high]
            refs.append(f"| {task} | {env} | {len(low)} | {fmt_num(lo[0])} ± {fmt_num(lo[1])} "
                        f"| {fmt_num(hi[0])} ± {fmt_num(hi[1])} | {fmt_num(gap)} "
                        f"| {fmt_pct(min(per_seed))} to {fmt_pct(max(per_seed))} | {sum(g <= 0 for g in per_seed)} |")
    return "\n".join(lines), "\n".join(refs)


def structure_table(rows: Sequence[Mapping], tasks: Sequence[str]) -> str:
    """Per task, what decides it: the best expert's control cost, its transient and sustained parts (the
    sustained share), the noise floor and the two headroom rows against it (geometric,
    :mod:`training.limits`), on ``lawn/Joint-v0``."""
    lines = [f"| task | {SCORE_HIGH} cost | transient | sustained (share) | "
             + " | ".join(f"{p} vs {SCORE_HIGH} (geometric, seeds won)" for p in REFERENCE_ROWS) + " |",
             "|" + "---|" * (4 + len(REFERENCE_ROWS))]
    for task in tasks:
        high = [r for r in rows if r["policy"] == SCORE_HIGH and r["env"] == JOINT and r.get("task") == task]
        if not high:
            continue
        total = sum(float(r["control_cost"]) for r in high)
        share = sum(float(r["sustained_cost"]) for r in high) / total
        cells = [mean_cell(rows, SCORE_HIGH, JOINT, task, m) for m in ("control_cost", "transient_cost",
                                                                       "sustained_cost")]
        cells[2] += f" ({share * 100:.0f} %)"
        for p in REFERENCE_ROWS:
            cost = costs_of(rows, p, JOINT, task)
            cells.append(fmt_geometric(geometric(rows, p, SCORE_HIGH, JOINT, task)) if cost else "–")
        lines.append(f"| {task} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def task_tables(rows: Sequence[Mapping], policies: Sequence[str], tasks: Sequence[str],
                skipped: Mapping[tuple[str, str], str]) -> str:
    """One Markdown table per task: every row's control cost, its transient and sustained parts, the
    score, and the comparison with the best expert on the same env (geometric, the deciding statistic,
    and the paired mean of relative differences)."""
    scores = scores_by_policy(rows)
    out = []
    for task in tasks:
        lines = [f"**{task}**", "", f"| policy | env | control cost | transient | sustained | score v{SCORE_VERSION} "
                 f"[95 %] | vs {SCORE_HIGH} (geometric, seeds won) | vs {SCORE_HIGH} (paired mean) |",
                 "|" + "---|" * 8]
        names = list(dict.fromkeys([SCORE_HIGH, SCORE_LOW, *REFERENCE_ROWS, *policies]))
        for env in dict.fromkeys(r["env"] for r in rows if r.get("task") == task):
            for p in names:
                if (task, p) in skipped or not costs_of(rows, p, env, task):
                    continue
                cells = [mean_cell(rows, p, env, task, m) for m in ("control_cost", "transient_cost", "sustained_cost")]
                cells.append(format_score(scores.get((task, env, p))))
                if p == SCORE_HIGH:
                    cells += ["–", "–"]
                else:
                    mean, half, _ = paired_difference(costs_of(rows, p, env, task), costs_of(rows, SCORE_HIGH, env, task))
                    cells += [fmt_geometric(geometric(rows, p, SCORE_HIGH, env, task)), fmt_paired(mean, half)]
                lines.append(f"| {p} | {env} | " + " | ".join(cells) + " |")
        out.append("\n".join(lines))
    return "\n\n".join(out)


def plot_profiles(per_slot: Sequence[Mapping], path: Path, tasks: Sequence[str],
                  transient_slots: int = TRANSIENT_SLOTS) -> Path:
    """The mean stage cost per slot of the experts, baselines, anchors, reference rows and agents on
    ``lawn/Joint-v0`` (the agents on their own env), one panel per task, log scale; from the rows of
    ``per_slot.csv`` (:func:`per_slot_profile`)."""
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


def write_leaderboard(path: Path, board: str, refs: str, skipped: Mapping[tuple[str, str], str], episodes: int,
                      seconds: float, workers: int, tasks: Sequence[str] = presets.SUITE, structure: str = "",
                      details: str = "", figure: Path | None = None, transient_slots: int = TRANSIENT_SLOTS) -> Path:
    """docs/LEADERBOARD.md (:data:`_PAGE`): the protocol, the board over ``tasks``, each task's cost
    structure, noise floor and headroom, every row per task, the references, what could not run."""
    from .provenance import provenance

    reasons = skipped_summary(skipped)
    picture = "" if figure is None else \
        f"\n![Mean stage cost per slot, per task](figures/{Path(figure).name})\n\n*The mean stage cost per slot over " \
        f"the test seeds (log scale), experts, baselines, anchors and reference rows on `lawn/Joint-v0`, learned " \
        f"agents on their own env; the dotted line is the transient/sustained split.*\n"
    text = _PAGE.format(
        provenance=provenance(), minutes=seconds / 60, workers=workers, suite_version=presets.SUITE_VERSION,
        names=", ".join(f"`{t}`" for t in presets.SUITE), last_seed=episodes - 1, score_version=SCORE_VERSION,
        subset="" if list(tasks) == list(presets.SUITE) else
        f" This board runs {', '.join(f'`{t}`' for t in tasks)} only (`--tasks`).",
        board=board, reasons=": " + "; ".join(reasons) + "." if reasons else ".", split=f"slots 0-{transient_slots - 1}",
        structure=structure, picture=picture, details=details, refs=refs, low=SCORE_LOW, high=SCORE_HIGH,
        refrows=", ".join(f"`{r}`" for r in REFERENCE_ROWS))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


#: The leaderboard page; :func:`write_leaderboard` fills its fields.
_PAGE = """# Leaderboard: the task suite

Generated by `lawn benchmark --suite --docs docs` (`bash scripts/refresh_docs.sh --only suite`) at
{provenance}, in {minutes:.1f} min with {workers} workers.

Suite v{suite_version} (`lawn_env.presets.SUITE`): {names};{subset} each task is a preset,
`gym.make("lawn/Comm-v0", config="steady")` runs it ([the benchmark protocol](benchmark.md) says why
these tasks). Every policy plays full episodes of the unmodified scenario on the test seeds
0-{last_seed} of every task; learned agents were trained on `default` only, so the other tasks
measure how they generalize.

Score v{score_version} (`training/score.py`), D4RL's normalized score adapted to a cost:
100 × (mean cost of `{low}` − mean cost) / (mean cost of `{low}` − mean cost of `{high}`), on the
same seeds, task and env (the numerator paired per seed); 0 is the paper's equal-power baseline,
100 the package's best expert, above 100 beats it (docs/benchmark.md, "Score versions"). The interval is a 95 % paired bootstrap over
seeds. The last column is the headline, rliable's aggregate: the interquartile mean of the
per-task scores with a 95 % stratified bootstrap interval (seeds resampled within each task).
Experts, baselines, anchors and the reference rows act on `lawn/Joint-v0`; each learned agent on
its own env. On `lawn/Comm-v0`, whose AGVs apply the paper's law, `{high}` plans as `rg-mpc`
does (the power and the drone for those AGVs), so 100 on a Comm row is that planner's. {refrows} are references, not
policies ([headroom rows](benchmark.md#headroom-and-noise-floor)).

{board}

n/a: the policy cannot act on the task{reasons} –: no score
(the references do not separate on that task's seeds, training/score.py).

## What decides each task

`{high}`'s control cost split into the transient ({split}) and the sustained part, and the three
reference rows against it, each as the geometric mean of the per-seed cost ratios − 1 with its
95 % bootstrap interval and the share of seeds won (the deciding statistic): a difference between
two policies smaller than the noise floor's is not one; the headroom rows say how much of the cost
the drone's reach and the links decide under the expert's own planning.

{structure}
{picture}
## Every row, per task

Control cost, its transient and sustained parts (mean ± 95 % t-interval), the score, and the
comparison with `{high}` on the same env and seeds: geometric (deciding) and as the mean of per-seed
relative differences (t-interval), which the few seeds where one cost is many times the other can
dominate.

{details}

## The references

Per task and env (mean control cost ± 95 % interval):

{refs}

## Adding a row

Train on the default task (`lawn train ...`), then

```bash
lawn benchmark --suite --include runs/my-agent        # or --policies sb3:DIR / zoo:NAME
```

prints this table with your agent's row (the same seeds, tasks and references) and writes
`runs/suite/episodes.csv`; a pull request that adds the agent to `agents/zoo/` adds the row here.
"""
