"""The benchmark protocol of learned agents and the task suite.

**Learned protocol** (``lawn benchmark --protocol learned``, the tables of ``lawn zoo build``):
every agent plays full 120-slot episodes of the unmodified scenario on the test seeds
0..:data:`~training.protocol.TEST_EPISODES`-1 (model selection uses the validation seeds
500000 + i, training 1000000 + ...), beside the best expert (:data:`~training.score.SCORE_HIGH`), ``epa`` and the zero action of every
interface the agents act through (``anchor:NAME``, :mod:`agents.anchors`) on the same seeds and
env. Each row reports the realized control cost, the normalized score (:mod:`training.score`),
the paired relative difference against the expert and against the agent's own anchor: what
learning adds is the last column.

The task suite (``lawn benchmark --suite``) is :mod:`training.suite`; both share the rows and
cells of this module.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from agents import make_policy
from agents.anchors import anchor_name
from agents.base import JOINT
from agents.learned import zoo_agents
from agents.runs import read_run
from lawn_env import ScenarioConfig, central_env_id

from .evaluate import TRANSIENT_SLOTS, evaluate, write_rows
from .protocol import TEST_EPISODES
from .score import SCORE_HIGH, SCORE_LOW, SCORE_VERSION, format_score, scores_by_policy
from .tables import Geometric, fmt_geometric, fmt_num, fmt_paired, fmt_pct, mean_ci, paired_difference, paired_geometric

__all__ = ["own_anchor", "policy_env", "costs_of", "paired", "protocol_cells", "learned_entries", "run_entries",
           "learned_table", "run_learned_protocol",
           "per_slot_profile", "geometric", "mean_cell"]

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
                progress: bool = True, task: str = "default", desc: str = "benchmark",
                transient_slots: int = TRANSIENT_SLOTS, profiles: list[dict] | None = None) -> list[dict]:
    """Full episodes of every (policy, env) entry on every seed; rows with a ``task`` column and
    without the per-slot trace (its mean per slot appended to ``profiles`` when given,
    :func:`per_slot_profile`)."""
    tasks = [(policy, env, config, int(s), {}) for policy, env in entries for s in seeds]
    rows = evaluate(tasks, workers=workers, progress=progress, desc=desc, transient_slots=transient_slots)
    for row in rows:
        row["task"] = task
    if profiles is not None:
        profiles += per_slot_profile(rows)
    for row in rows:
        for key in _DROPPED:
            row.pop(key, None)
    return rows


def costs_of(rows: Sequence[Mapping], policy: str, env: str, task: str | None = None,
             metric: str = "control_cost") -> dict[int, float]:
    """``metric`` (default: the control cost) per seed of ``policy`` on ``env`` (and ``task``, when
    given) in evaluation rows."""
    return {int(r["seed"]): float(r[metric]) for r in rows
            if r["policy"] == policy and r["env"] == env and (task is None or r.get("task", "default") == task)}


def geometric(rows: Sequence[Mapping], policy: str, reference: str, env: str, task: str | None = None) -> Geometric:
    """The geometric mean of ``policy``'s per-seed cost ratios against ``reference``, its bootstrap
    interval and the share of seeds won (:func:`training.tables.paired_geometric`)."""
    return paired_geometric(costs_of(rows, policy, env, task), costs_of(rows, reference, env, task))


def mean_cell(rows: Sequence[Mapping], policy: str, env: str, task: str | None, metric: str) -> str:
    """``mean ± 95 % half-width`` of ``metric`` over the seeds of ``policy`` on ``env`` (and ``task``)."""
    mean, half = mean_ci(costs_of(rows, policy, env, task, metric).values())
    return f"{fmt_num(mean)} ± {fmt_num(half)}"


def paired(rows: Sequence[Mapping], policy: str, reference: str, env: str) -> tuple[float, float]:
    """Mean per-seed relative difference of ``policy``'s cost against ``reference``'s and its 95 % half-width."""
    mean, half, _ = paired_difference(costs_of(rows, policy, env), costs_of(rows, reference, env))
    return mean, half


def protocol_cells(rows: Sequence[Mapping], scores: Mapping, policy: str, env: str) -> dict[str, str]:
    """The cells every learned-protocol table shows for ``policy`` on ``env``: its anchor, control
    cost, score, paired difference against the best expert and against its own anchor, and its worst seed
    against the anchor."""
    cost = costs_of(rows, policy, env)
    anchor = own_anchor(policy)
    cells = {"anchor": anchor or "–", "cost": mean_cell(rows, policy, env, None, "control_cost"),
             "score": format_score(scores.get(("default", env, policy))),
             "vs_ref": "–" if policy == SCORE_HIGH else fmt_paired(*paired(rows, policy, SCORE_HIGH, env)),
             "vs_anchor": "–", "worst": "–", "geo_ref": "–", "geo_anchor": "–"}
    cells["transient"] = mean_cell(rows, policy, env, None, "transient_cost")
    cells["sustained"] = mean_cell(rows, policy, env, None, "sustained_cost")
    if policy != SCORE_HIGH:
        cells["geo_ref"] = fmt_geometric(geometric(rows, policy, SCORE_HIGH, env))
    if anchor is not None:
        base = costs_of(rows, anchor, env)
        cells["vs_anchor"] = fmt_paired(*paired(rows, policy, anchor, env))
        cells["geo_anchor"] = fmt_geometric(geometric(rows, policy, anchor, env))
        cells["worst"] = fmt_pct(max((cost[s] - base[s]) / base[s] for s in cost if s in base))
    return cells


def learned_table(rows: Sequence[Mapping], entries: Sequence[tuple[str, str]],
                  labels: Mapping[str, str] | None = None) -> str:
    """The learned protocol's Markdown table of ``entries`` from their rows."""
    scores = scores_by_policy(rows)
    seeds = len({int(r["seed"]) for r in rows})
    lines = [f"| policy | env | acts around | control cost | transient | sustained | score v{SCORE_VERSION} [95 %] "
             f"| vs {SCORE_HIGH} (geometric, seeds won) | vs own anchor (geometric, seeds won) | vs {SCORE_HIGH} (paired mean) "
             f"| vs own anchor (paired mean) | worst seed vs own anchor |", "|" + "---|" * 12]
    for policy, env in entries:
        c = protocol_cells(rows, scores, policy, env)
        name = (labels or {}).get(policy, policy)
        lines.append(f"| {name} | {env} | {c['anchor']} | {c['cost']} | {c['transient']} | {c['sustained']} "
                     f"| {c['score']} | {c['geo_ref']} | {c['geo_anchor']} | {c['vs_ref']} | {c['vs_anchor']} "
                     f"| {c['worst']} |")
    split = rows[0]["transient_slots"]
    lines += ["", f"{seeds} test seeds; control cost split into the transient (slots 0-{split - 1}) and the sustained "
              f"part (slots {split} on); score v{SCORE_VERSION}: 0 = {SCORE_LOW}, 100 = {SCORE_HIGH} "
              "(training/score.py); geometric columns (the deciding statistic, docs/benchmark.md): the geometric "
              "mean of the per-seed cost ratios - 1 with its 95 % bootstrap interval and the share of seeds won; "
              "paired-mean columns: the mean per-seed relative difference and its 95 % t-interval."]
    return "\n".join(lines)


def run_learned_protocol(agents: Sequence[str], out_dir: Path, episodes: int = TEST_EPISODES, workers: int = 1,
                         progress: bool = True, config: ScenarioConfig | None = None,
                         transient_slots: int = TRANSIENT_SLOTS) -> str:
    """The learned protocol over ``agents`` (default: every shipped agent); writes
    ``episodes.csv`` and ``summary.md`` into ``out_dir`` and returns the table with its runtime."""
    start = time.perf_counter()
    agents = list(agents) or [f"zoo:{n}" for n in zoo_agents()]
    config = config or ScenarioConfig()
    entries = learned_entries(agents)
    for policy, env in entries:
        make_policy(policy, config, env_id=env)  # a bad name or a mismatched agent fails before any episode
    rows = run_entries(entries, config, range(episodes), workers, progress, desc="learned protocol",
                       transient_slots=transient_slots)
    table = learned_table(rows, entries) + f" Runtime {time.perf_counter() - start:.0f} s with {workers} workers."
    out_dir = Path(out_dir)
    write_rows(rows, out_dir / "episodes.csv")
    (out_dir / "summary.md").write_text(table + "\n")
    return table


def per_slot_profile(rows: Sequence[Mapping]) -> list[dict]:
    """The mean stage cost per slot over the episodes of every (task, env, policy) of rows that
    hold their per-slot trace (``stage_costs``): one row per slot."""
    groups: dict[tuple[str, str, str], list[list[float]]] = {}
    for r in rows:
        key = (str(r.get("task", "default")), str(r["env"]), str(r["policy"]))
        groups.setdefault(key, []).append(json.loads(r["stage_costs"]))
    out = []
    for (task, env, policy), traces in groups.items():
        mean = np.mean(np.asarray(traces, dtype=float), axis=0)
        out += [{"task": task, "env": env, "policy": policy, "slot": n, "mean_stage_cost": float(c),
                 "episodes": len(traces)} for n, c in enumerate(mean)]
    return out
