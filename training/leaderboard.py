"""The benchmark protocol of learned agents and the task suite.

**Learned protocol** (``lawn benchmark --protocol learned``, the tables of ``lawn zoo build``):
every agent plays full 120-slot episodes of the unmodified scenario on the test seeds
0..:data:`~training.protocol.TEST_EPISODES`-1 (model selection uses the validation seeds
500000 + i, training 1000000 + ...), beside ``rg-mpc``, ``epa`` and the zero action of every
interface the agents act through (``anchor:NAME``, :mod:`agents.anchors`) on the same seeds and
env. Each row reports the realized control cost, the normalized score (:mod:`training.score`),
the paired relative difference against ``rg-mpc`` and against the agent's own anchor: what
learning adds is the last column.

**Task suite** (``lawn benchmark --suite``, docs/LEADERBOARD.md): the presets of
:data:`lawn_env.presets.SUITE`, every expert, baseline, shipped agent and the stake and distance
anchors on each, scored against the references of the same task and env. Agents trained on the
default task are run on every task; where one cannot act (its network was built for K = 4) the
table says so.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from agents import make_policy
from agents.anchors import anchor_name
from agents.base import JOINT
from agents.errors import MissingExtra
from agents.learned import zoo_agents
from agents.runs import read_run
from lawn_env import ScenarioConfig, central_env_id, presets

from .evaluate import evaluate, write_rows
from .protocol import TEST_EPISODES
from .score import SCORE_HIGH, SCORE_LOW, SCORE_VERSION, format_score, scores_by_policy
from .tables import fmt_num, fmt_paired, fmt_pct, mean_ci, paired_difference

__all__ = ["own_anchor", "policy_env", "costs_of", "paired", "protocol_cells", "learned_entries", "run_entries",
           "learned_table", "run_learned_protocol",
           "SUITE_POLICIES", "suite_policies", "run_suite", "suite_table", "skipped_summary", "write_leaderboard"]

#: Rows without a per-slot trace keep the saved tables small (100 seeds x many agents).
_DROPPED = ("stage_costs",)


def policy_env(policy: str) -> str:
    """The env a policy is benchmarked on: a learned agent's own (multi-agent agents drive
    ``lawn/Joint-v0``), ``lawn/Joint-v0`` for everything else."""
    prefix, _, rest = policy.partition(":")
    if prefix == "zoo":
        agents = zoo_agents()
        if rest not in agents:
            raise ValueError(f"unknown zoo agent {rest!r}; shipped: {', '.join(agents)}")
        return agents[rest]["evaluated_on"]
    if prefix in ("sb3", "bc", "marl"):
        env = read_run(rest).env
        return central_env_id(env)
    return JOINT


def own_anchor(policy: str) -> str | None:
    """The ``anchor:NAME`` whose zero action a learned agent acts around (from its recorded training
    interface); None for experts, baselines and anchors."""
    prefix, _, rest = policy.partition(":")
    if prefix == "zoo":
        return anchor_name(zoo_agents()[rest].get("interface"))
    if prefix in ("sb3", "bc", "marl"):
        return anchor_name(read_run(rest).interface)
    return None


def learned_entries(agents: Sequence[str], envs: Sequence[str] | None = None) -> list[tuple[str, str]]:
    """(policy, env) pairs of the learned protocol: per env, the two references, the anchors the
    env's agents act around, then the agents."""
    by_env: dict[str, list[str]] = {env: [] for env in (envs or ())}
    for agent in dict.fromkeys(agents):  # a repeated agent is one row
        by_env.setdefault(policy_env(agent), []).append(agent)
    out: list[tuple[str, str]] = []
    for env, members in by_env.items():
        anchors = sorted({a for a in map(own_anchor, members) if a is not None})
        out += [(p, env) for p in (SCORE_HIGH, SCORE_LOW, *anchors, *members)]
    return out


def run_entries(entries: Sequence[tuple[str, str]], config: ScenarioConfig, seeds: Sequence[int], workers: int = 1,
                progress: bool = True, task: str = "default", desc: str = "benchmark") -> list[dict]:
    """Full episodes of every (policy, env) entry on every seed; rows with a ``task`` column and
    without the per-slot trace."""
    tasks = [(policy, env, config, int(s), {}) for policy, env in entries for s in seeds]
    rows = evaluate(tasks, workers=workers, progress=progress, desc=desc)
    for row in rows:
        row["task"] = task
        for key in _DROPPED:
            row.pop(key, None)
    return rows


def costs_of(rows: Sequence[Mapping], policy: str, env: str, task: str | None = None) -> dict[int, float]:
    """Control cost per seed of ``policy`` on ``env`` (and ``task``, when given) in evaluation rows."""
    return {int(r["seed"]): float(r["control_cost"]) for r in rows
            if r["policy"] == policy and r["env"] == env and (task is None or r.get("task", "default") == task)}


def paired(rows: Sequence[Mapping], policy: str, reference: str, env: str) -> tuple[float, float]:
    """Mean per-seed relative difference of ``policy``'s cost against ``reference``'s and its 95 % half-width."""
    mean, half, _ = paired_difference(costs_of(rows, policy, env), costs_of(rows, reference, env))
    return mean, half


def protocol_cells(rows: Sequence[Mapping], scores: Mapping, policy: str, env: str) -> dict[str, str]:
    """The cells every learned-protocol table shows for ``policy`` on ``env``: its anchor, control
    cost, score, paired difference against rg-mpc and against its own anchor, and its worst seed
    against the anchor."""
    cost = costs_of(rows, policy, env)
    mean, half = mean_ci(cost.values())
    anchor = own_anchor(policy)
    cells = {"anchor": anchor or "–", "cost": f"{fmt_num(mean)} ± {fmt_num(half)}",
             "score": format_score(scores.get(("default", env, policy))),
             "vs_ref": "–" if policy == SCORE_HIGH else fmt_paired(*paired(rows, policy, SCORE_HIGH, env)),
             "vs_anchor": "–", "worst": "–"}
    if anchor is not None:
        base = costs_of(rows, anchor, env)
        cells["vs_anchor"] = fmt_paired(*paired(rows, policy, anchor, env))
        cells["worst"] = fmt_pct(max((cost[s] - base[s]) / base[s] for s in cost if s in base))
    return cells


def learned_table(rows: Sequence[Mapping], entries: Sequence[tuple[str, str]],
                  labels: Mapping[str, str] | None = None) -> str:
    """The learned protocol's Markdown table of ``entries`` from their rows."""
    scores = scores_by_policy(rows)
    seeds = len({int(r["seed"]) for r in rows})
    lines = [f"| policy | env | acts around | control cost | score v{SCORE_VERSION} [95 %] | vs rg-mpc (paired) "
             f"| vs own anchor (paired) | worst seed vs own anchor |", "|" + "---|" * 8]
    for policy, env in entries:
        c = protocol_cells(rows, scores, policy, env)
        name = (labels or {}).get(policy, policy)
        lines.append(f"| {name} | {env} | {c['anchor']} | {c['cost']} | {c['score']} | {c['vs_ref']} "
                     f"| {c['vs_anchor']} | {c['worst']} |")
    lines += ["", f"{seeds} test seeds; score v{SCORE_VERSION}: 0 = {SCORE_LOW}, 100 = {SCORE_HIGH} "
              "(training/score.py); paired columns: mean per-seed relative difference in control cost and its "
              "95 % t-interval."]
    return "\n".join(lines)


def run_learned_protocol(agents: Sequence[str], out_dir: Path, episodes: int = TEST_EPISODES, workers: int = 1,
                         progress: bool = True, config: ScenarioConfig | None = None) -> str:
    """The learned protocol over ``agents`` (default: every shipped agent); writes
    ``episodes.csv`` and ``summary.md`` into ``out_dir`` and returns the table with its runtime."""
    start = time.perf_counter()
    agents = list(agents) or [f"zoo:{n}" for n in zoo_agents()]
    config = config or ScenarioConfig()
    entries = learned_entries(agents)
    for policy, env in entries:
        make_policy(policy, config, env_id=env)  # a bad name or a mismatched agent fails before any episode
    rows = run_entries(entries, config, range(episodes), workers, progress, desc="learned protocol")
    table = learned_table(rows, entries) + f" Runtime {time.perf_counter() - start:.0f} s with {workers} workers."
    out_dir = Path(out_dir)
    write_rows(rows, out_dir / "episodes.csv")
    (out_dir / "summary.md").write_text(table + "\n")
    return table


# ---------------------------------------------------------------------- the task suite
#: Experts and baselines of the suite (global-mpc, seconds per slot, is the gap study's reference).
SUITE_POLICIES = ("rg-mpc", "ao-mpc", "epa", "sf", "pid", "lqr", "heuristic", "anchor:stake", "anchor:distance")


def suite_policies() -> list[str]:
    """The experts, baselines and anchors of :data:`SUITE_POLICIES` (``anchor:hover`` left out: its
    cost is thousands of times rg-mpc's) and every shipped agent."""
    return list(SUITE_POLICIES) + [f"zoo:{n}" for n in zoo_agents()]


def _applicable(policy: str, env: str, config: ScenarioConfig) -> str | None:
    """None when ``policy`` can act on ``env`` with ``config``, else why not (one line). Names are
    checked on the default task first (by the caller), so a typo is an error, not an n/a."""
    try:
        make_policy(policy, config, env_id=env)
    except (ValueError, MissingExtra) as exc:  # a network built for another K; torch not installed
        return str(exc)
    return None


def run_suite(policies: Sequence[str], tasks: Sequence[str], episodes: int, out_dir: Path, workers: int = 1,
              progress: bool = True) -> tuple[list[dict], dict[tuple[str, str], str], float]:
    """Every policy on every task (seeds 0..episodes-1), with the references of each env used;
    writes ``episodes.csv``. Returns the rows, the (task, policy) pairs that cannot run with the
    reason, and the wall time."""
    start = time.perf_counter()
    policies = list(dict.fromkeys(policies))
    envs = {p: policy_env(p) for p in policies}
    for p in policies:  # unknown names and agents that cannot act on the default task are errors
        make_policy(p, ScenarioConfig(), env_id=envs[p])
    rows: list[dict] = []
    skipped: dict[tuple[str, str], str] = {}
    for task in tasks:
        config = presets.get(task)
        entries = [(p, env) for env in dict.fromkeys(envs.values()) for p in (SCORE_HIGH, SCORE_LOW)]
        for p in policies:
            reason = _applicable(p, envs[p], config)
            if reason is not None:
                skipped[(task, p)] = reason
            elif (p, envs[p]) not in entries:
                entries.append((p, envs[p]))
        rows += run_entries(entries, config, range(episodes), workers, progress, task=task, desc=f"suite: {task}")
    write_rows(rows, Path(out_dir) / "episodes.csv")
    return rows, skipped, time.perf_counter() - start


def suite_table(rows: Sequence[Mapping], policies: Sequence[str], tasks: Sequence[str],
                skipped: Mapping[tuple[str, str], str]) -> tuple[str, str]:
    """The leaderboard (score per task, mean over tasks) and the references' costs per task."""
    scores = scores_by_policy(rows)
    lines = ["| policy | env | " + " | ".join(tasks) + " | mean over tasks |", "|" + "---|" * (len(tasks) + 3)]
    for p in policies:
        env = policy_env(p)
        cells, means = [], []
        for task in tasks:
            score = scores.get((task, env, p))
            if (task, p) in skipped or score is None:
                cells.append("n/a" if (task, p) in skipped else "–")
                continue
            cells.append(format_score(score))
            means.append(score[0])
        overall = f"{np.mean(means):.1f}" if len(means) == len(tasks) else f"{np.mean(means):.1f} ({len(means)} tasks)" \
            if means else "–"
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


def skipped_summary(skipped: Mapping[tuple[str, str], str]) -> list[str]:
    """One line per task of the policies that cannot act there, with the first one's reason."""
    by_task: dict[str, list[str]] = {}
    for task, policy in skipped:
        by_task.setdefault(task, []).append(policy)
    return [f"on `{task}`: {', '.join(ps)} ({skipped[(task, ps[0])]})" for task, ps in by_task.items()]


def write_leaderboard(path: Path, board: str, refs: str, skipped: Mapping[tuple[str, str], str], episodes: int,
                      seconds: float, workers: int, tasks: Sequence[str] = presets.SUITE) -> Path:
    """docs/LEADERBOARD.md: the protocol, the board over ``tasks``, the references, what could not run."""
    from .provenance import provenance

    reasons = skipped_summary(skipped)
    subset = "" if list(tasks) == list(presets.SUITE) else \
        f" This board runs {', '.join(f'`{t}`' for t in tasks)} only (`--tasks`)."
    tasks = ", ".join(f"`{t}`" for t in presets.SUITE)
    text = f"""# Leaderboard: the task suite

Generated by `lawn benchmark --suite --docs docs` (`bash scripts/refresh_docs.sh --only suite`) at
{provenance()}, in {seconds / 60:.1f} min with {workers} workers.

Suite v{presets.SUITE_VERSION} (`lawn_env.presets.SUITE`): {tasks};{subset} each task is a preset,
`gym.make("lawn/Comm-v0", config="k8")` runs it. Every policy plays full 120-slot episodes of
the unmodified scenario on the test seeds 0-{episodes - 1} of every task; learned agents were
trained on `default` only, so the other tasks measure how they generalize.

Score v{SCORE_VERSION} (`training/score.py`), D4RL's normalized score adapted to a cost:
100 × (mean cost of `epa` − mean cost) / (mean cost of `epa` − mean cost of `rg-mpc`), on the
same seeds, task and env (the numerator paired per seed); 0 is the paper's equal-power baseline,
100 the package's best expert, above 100 beats it. The interval is a 95 % paired bootstrap over
seeds. Experts, baselines and anchors act on `lawn/Joint-v0`; each learned agent on its own env.

{board}

n/a: the policy cannot act on the task{': ' + '; '.join(reasons) + '.' if reasons else '.'} –: no score
(the references do not separate on that task's seeds, training/score.py).

The references, per task and env (mean control cost ± 95 % interval):

{refs}

## Adding a row

Train on the default task (`lawn train ...`), then

```bash
lawn benchmark --suite --include runs/my-agent        # or --policies sb3:DIR / zoo:NAME
```

prints this table with your agent's row (the same seeds, tasks and references) and writes
`runs/suite/episodes.csv`; a pull request that adds the agent to `agents/zoo/` adds the row here.
"""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path
