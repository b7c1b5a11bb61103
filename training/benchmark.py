"""``lawn benchmark``'s protocols, each a composition of :mod:`training.results`: play the entries
(:mod:`.results.run`), compute (:mod:`.results.stats`), write the tables (:mod:`.results.report`).

* **Paper protocol** (:func:`run_benchmark`): the policies on the same seeds of one scenario,
  compared with the first per seed and scored. Every row of the README's table replays two recorded
  episodes (:func:`digest_records`, ``tests/data/episode_digests.json``), so a change of any
  policy's episodes is deliberate or a test failure; ``python -m training.benchmark
  --write-digests`` records them.
* **Learned protocol** (:func:`run_learned_protocol`, ``lawn zoo build``): every agent on the test
  seeds beside the best expert, ``epa`` and the zero action of the interface it acts through.
* **Task suite** (:func:`run_suite`, docs/LEADERBOARD.md): experts, baselines, shipped agents and
  the reference rows on every preset of :data:`lawn_env.presets.SUITE`; an agent that cannot act on
  a task (a network built for K = 4) is reported as such.
* **Fleet sizes** (:func:`run_generalization`, docs/LEARNED.md): the networks that read the entity
  layout on K = 3..64 AGVs beside the best expert and its noise floor.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from agents import BENCHMARK_POLICIES, make_policy
from agents.base import JOINT
from agents.errors import MissingExtra
from agents.learned import zoo_agents
from lawn_env import ScenarioConfig, presets

from .protocol import TEST_EPISODES
from .recipes import RECIPES
from .results.ranges import test_seeds
from .results.report import learned_table, plot_summary, summary_markdown
from .results.run import (
    DEFAULT_PLAY,
    NOISE,
    REFERENCE_ROWS,
    Play,
    build_policy,
    evaluate,
    learned_entries,
    policy_env,
    run_entries,
    run_episode,
    write_rows,
)
from .results.stats import (
    SCORE_HIGH,
    SCORE_LOW,
    paired_cost_difference,
    paired_cost_geometric,
    scores_by_policy,
    summarize,
)

__all__ = ["run_benchmark", "README_ROWS", "DIGESTS", "DIGEST_SEEDS", "episode_record", "digest_records",
           "run_learned_protocol", "SUITE_POLICIES", "suite_policies", "run_suite", "FLEET_SIZES",
           "fleet_agents", "run_generalization"]

#: Experts and baselines of the suite (global-mpc, seconds per slot, is the gap study's reference).
SUITE_POLICIES = ("dv-mpc", "rg-mpc", "ao-mpc", "epa", "sf", "pid", "lqr", "heuristic", "anchor:stake",
                  "anchor:distance")
#: The rows of the README's table: lawn benchmark's default policies and the reference rows.
README_ROWS = (*BENCHMARK_POLICIES, *REFERENCE_ROWS)
#: Their recorded episodes (seeds DIGEST_SEEDS of the default task on lawn/Joint-v1).
DIGESTS = Path(__file__).resolve().parent.parent / "tests" / "data" / "episode_digests.json"
DIGEST_SEEDS = (0, 1)
#: Fleet size -> test seeds (0..n-1) of the fleet-size table.
FLEET_SIZES: dict[int, int] = {3: 100, 4: 100, 8: 100, 16: 40, 32: 40, 64: 20}
#: How the fleet-size table is played by default: two processes.
FLEET_PLAY = Play(workers=2)


def run_benchmark(policies: Sequence[str], env_id: str, config: ScenarioConfig, episodes: int, seed: int,
                  out_dir: Path, play: Play = DEFAULT_PLAY) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """Run every policy on seeds ``seed .. seed+episodes-1``; write ``episodes.csv``,
    ``summary.csv``, ``summary.md`` and ``benchmark.png`` into ``out_dir``. With ``epa`` and
    ``dv-mpc`` among the policies, the summary has the normalized score; every policy is compared
    with the first, per seed, as a mean of relative differences and as a geometric mean of cost
    ratios (the deciding statistic, docs/benchmark.md)."""
    tasks: list[tuple[Any, ...]] = [(name, env_id, config, seed + i, {}) for name in policies for i in range(episodes)]
    rows = evaluate(tasks, play.workers, play.progress, "benchmark", play.transient_slots)
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


def episode_record(policy: str, seed: int) -> dict[str, Any]:
    """One seeded episode of a README row on the default task: its digest and its control cost."""
    row = run_episode(policy, JOINT, ScenarioConfig(), seed)
    values = [f"{float(x):.10g}" for x in (*json.loads(row["stage_costs"]), row["outage_rate"], row["rmse_m"])]
    return {"seed": seed, "control_cost": float(f"{float(row['control_cost']):.10g}"),
            "digest": hashlib.sha256(" ".join(values).encode()).hexdigest()[:16]}


def digest_records(rows: Sequence[str] = README_ROWS) -> dict[str, list[dict[str, Any]]]:
    """Every row's episodes (:func:`episode_record`), by row name."""
    return {name: [episode_record(name, s) for s in DIGEST_SEEDS] for name in rows}


def run_learned_protocol(agents: Sequence[str], out_dir: Path, episodes: int = TEST_EPISODES, play: Play = DEFAULT_PLAY,
                         config: ScenarioConfig | None = None) -> str:
    """The learned protocol over ``agents`` (default: every shipped agent); writes
    ``episodes.csv`` and ``summary.md`` into ``out_dir`` and returns the table with its runtime."""
    start = time.perf_counter()
    agents = list(agents) or [f"zoo:{n}" for n in zoo_agents()]
    config = config or ScenarioConfig()
    entries = learned_entries(agents)
    for policy, env in entries:
        make_policy(policy, config, env_id=env)  # a bad name or a mismatched agent fails before any episode
    rows = run_entries(entries, config, range(episodes), play, desc="learned protocol")
    table = learned_table(rows, entries) + f" Runtime {time.perf_counter() - start:.0f} s with {play.workers} workers."
    out_dir = Path(out_dir)
    write_rows(rows, out_dir / "episodes.csv")
    (out_dir / "summary.md").write_text(table + "\n")
    return table


def suite_policies() -> list[str]:
    """The experts, baselines and anchors of :data:`SUITE_POLICIES` (``anchor:hover`` left out: its
    cost is thousands of times the experts') and every shipped agent that acts under the paper's
    control law."""
    return list(SUITE_POLICIES) + [f"zoo:{n}" for n, rec in zoo_agents().items() if _paper_law(rec)]


def _paper_law(record: Mapping[str, Any]) -> bool:
    """A shipped agent acts on the suite's tasks (the paper's control law): not one trained with the
    delivery law (``zoo:dv-joint``, ``zoo:dv-comm``: compared on their own tasks in docs/LEARNED.md)."""
    return bool(record.get("config", {}).get("control", {}).get("law", "paper") == "paper")


def _applicable(policy: str, env: str, config: ScenarioConfig) -> str | None:
    """None when ``policy`` can act on ``env`` with ``config``, else why not (one line). Names are
    checked on the default task first (by the caller), so a typo is an error, not an n/a."""
    try:
        build_policy(policy, config, env)
    except (ValueError, MissingExtra) as exc:  # a network built for another K; torch not installed
        return str(exc)
    return None


def run_suite(policies: Sequence[str], tasks: Sequence[str], episodes: int, out_dir: Path, play: Play = DEFAULT_PLAY
              ) -> tuple[list[dict[str, Any]], dict[tuple[str, str], str], float]:
    """Every policy on every task (seeds 0..episodes-1), with the references of each env used and
    the reference rows (:data:`.results.run.REFERENCE_ROWS`, on ``lawn/Joint-v1``); writes
    ``episodes.csv`` and ``per_slot.csv`` (the mean stage cost per slot of every task, env and
    policy). Returns the rows, the (task, policy) pairs that cannot run with the reason, and the
    wall time."""
    start = time.perf_counter()
    policies = list(dict.fromkeys(policies))
    envs = {p: policy_env(p) for p in policies}
    for p in policies:  # unknown names and agents that cannot act on the default task are errors
        build_policy(p, ScenarioConfig(), envs[p])
    rows: list[dict[str, Any]] = []
    profiles: list[dict[str, Any]] = []
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
        rows += run_entries(entries, config, range(episodes), play, task=task, desc=f"suite: {task}",
                            profiles=profiles)
    write_rows(rows, Path(out_dir) / "episodes.csv")
    write_rows(profiles, Path(out_dir) / "per_slot.csv")
    return rows, skipped, time.perf_counter() - start


def fleet_agents() -> list[str]:
    """The shipped agents whose network reads the entity layout (``zoo:NAME``) and was trained on the
    default scenario (not the distilled agents of the steady tasks: :func:`distil_agents`)."""
    return [f"zoo:{name}" for name, rec in zoo_agents().items()
            if (rec.get("interface") or {}).get("layout") == "entities" and name not in _distilled()]


def _distilled() -> list[str]:
    return [name for name, r in RECIPES.items() if r.section == "distil"]


def run_generalization(agents: Sequence[str], sizes: Mapping[int, int] = FLEET_SIZES, play: Play = FLEET_PLAY,
                       base: ScenarioConfig | None = None) -> list[dict[str, Any]]:
    """Full episodes of every agent, the best expert and its noise floor on the default task (or
    ``base``) with each fleet size (``task`` = ``k<K>``), on the first n seeds of both test ranges
    (:func:`training.results.ranges.test_seeds`, n per size)."""
    envs = list(dict.fromkeys(policy_env(a) for a in agents))
    noise = next(iter(NOISE))
    rows: list[dict[str, Any]] = []
    for k, seeds in sizes.items():
        config = (base or presets.get("default")).override(num_agvs=int(k))
        entries = [(p, env) for env in envs for p in (SCORE_HIGH, noise)] + [(a, policy_env(a)) for a in agents]
        rows += run_entries(entries, config, test_seeds(int(seeds)), play, task=f"k{k}", desc=f"fleet sizes: K = {k}")
    return rows


def main(argv: list[str] | None = None) -> int:
    """``python -m training.benchmark [--write-digests]``: compare the README rows' episodes with the
    recorded ones (exit 1 naming the rows that changed), or record them."""
    parser = argparse.ArgumentParser(prog="python -m training.benchmark", description=str(main.__doc__).split(":")[0])
    parser.add_argument("--write-digests", action="store_true", help=f"rewrite {DIGESTS.name}")
    args = parser.parse_args(argv)
    now = digest_records()
    if args.write_digests:
        DIGESTS.parent.mkdir(parents=True, exist_ok=True)
        tmp = DIGESTS.with_suffix(".tmp")
        tmp.write_text(json.dumps(now, indent=1) + "\n")
        tmp.replace(DIGESTS)
        print(f"wrote {DIGESTS}: {len(now)} rows x {len(DIGEST_SEEDS)} episodes")
        return 0
    recorded = json.loads(DIGESTS.read_text()) if DIGESTS.exists() else {}
    changed = [name for name in now if recorded.get(name) != now[name]]
    print("unchanged" if not changed else f"changed: {', '.join(changed)}")
    return 1 if changed else 0


if __name__ == "__main__":
    sys.exit(main())
