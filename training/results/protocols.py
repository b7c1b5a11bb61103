"""``lawn benchmark``'s protocols: which episodes to play (:class:`.episode.EpisodeSpec`,
:class:`.episode.Entry`), played by :mod:`.run`, reduced by :mod:`.stats`, written by :mod:`.report`.

* **Paper protocol** (:func:`run_benchmark`): the policies on the same seeds of one scenario,
  compared with the first per seed and scored. Every row of the README's table replays two recorded
  episodes (:func:`digest_records`, :data:`DIGESTS`), so a change of any policy's episodes is
  deliberate or a test failure; ``python -m training.results.protocols --write-digests`` records them.
* **Learned protocol** (:func:`run_learned_protocol`, ``lawn zoo build``): every agent on the test
  seeds beside the best expert, ``epa`` and the zero action of the interface it acts through.
* **Task suite** (:func:`run_suite`, :func:`suite_pages`, docs/LEADERBOARD.md): experts, baselines,
  shipped agents and the reference rows on every preset of :data:`lawn_env.presets.SUITE`; an agent
  that cannot act on a task (a network built for K = 4) is reported as such.
* **Fleet sizes** (:func:`run_generalization`, :func:`fleet_block`, docs/LEARNED.md): the networks
  that read the entity layout on K = 3..64 AGVs beside the best expert and its noise floor, with
  their targets (:data:`FLEET_TARGETS`).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import shutil
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

from agents import BENCHMARK_POLICIES, make_policy
from agents.base import JOINT
from agents.errors import MissingExtra
from agents.learned import zoo_agents
from lawn_env import ScenarioConfig, presets

from ..pages import block_names, replace_block
from ..protocol import TEST_EPISODES
from ..recipes import RECIPES
from .episode import DEFAULT_PLAY, Entry, EpisodeResult, EpisodeSpec, Play, write_results, write_rows
from .report import (
    fleet_table,
    learned_table,
    plot_profiles,
    plot_summary,
    skipped_summary,
    structure_table,
    suite_table,
    summary_markdown,
    task_tables,
)
from .run import (
    NOISE,
    REFERENCE_ROWS,
    build_policy,
    evaluate,
    learned_entries,
    policy_env,
    run_entries,
    run_episode,
)
from .stats import (
    SCORE_HIGH,
    SCORE_LOW,
    TEST_RANGES,
    RangeComparison,
    paired_cost_difference,
    paired_cost_geometric,
    reduce,
    scores_by_policy,
    summarize,
    test_seeds,
)

__all__ = ["run_benchmark", "README_ROWS", "DIGESTS", "DIGEST_SEEDS", "episode_record", "digest_records",
           "run_learned_protocol", "SUITE_POLICIES", "suite_policies", "run_suite", "Suite", "suite_pages",
           "SUITE_BLOCKS", "FLEET_SIZES", "FLEET_TARGETS", "FLEET_WORST", "fleet_agents", "fleet_target",
           "run_generalization", "fleet_block"]

#: Experts and baselines of the suite (global-mpc, seconds per slot, is the gap study's reference).
SUITE_POLICIES = ("dv-mpc", "rg-mpc", "ao-mpc", "epa", "sf", "pid", "lqr", "heuristic", "anchor:stake",
                  "anchor:distance")
#: The rows of the README's table: lawn benchmark's default policies and the reference rows.
README_ROWS = (*BENCHMARK_POLICIES, *REFERENCE_ROWS)
#: Their recorded episodes (seeds DIGEST_SEEDS of the default task on lawn/Joint-v1).
DIGESTS = Path(__file__).resolve().parent / "episode_digests.json"
DIGEST_SEEDS = (0, 1)
#: Fleet size -> test seeds (0..n-1 of each test range) of the fleet-size table.
FLEET_SIZES: dict[int, int] = {3: 100, 4: 100, 8: 100, 16: 40, 32: 40, 64: 20}
#: The fleet networks' targets against dv-mpc: the upper bound of the geometric interval, per K
#: (None: reported), on every range; and no seed over FLEET_WORST times dv-mpc's cost.
FLEET_TARGETS: dict[int, float | None] = {3: 0.05, 4: 0.05, 8: 0.05, 16: 0.10, 32: 0.10, 64: None}
FLEET_WORST = 3.0
#: How the fleet-size table is played by default: two processes.
FLEET_PLAY = Play(workers=2)
#: The suite's tables: the file each is written to in the output directory, and its block of LEADERBOARD.md.
SUITE_BLOCKS = {"board": "suite-board", "structure": "suite-structure", "tasks": "suite-tasks",
                "references": "suite-references"}


def run_benchmark(policies: Sequence[str], env_id: str, config: ScenarioConfig, episodes: int, seed: int,
                  out_dir: Path, play: Play = DEFAULT_PLAY) -> tuple[list[EpisodeResult], list[dict[str, Any]]]:
    """Run every policy on seeds ``seed .. seed+episodes-1``; write ``episodes.csv``,
    ``summary.csv``, ``summary.md`` and ``benchmark.png`` into ``out_dir``. With ``epa`` and
    ``dv-mpc`` among the policies, the summary has the normalized score; every policy is compared
    with the first, per seed, as a mean of relative differences and as a geometric mean of cost
    ratios (the deciding statistic, docs/benchmark.md)."""
    specs = [EpisodeSpec(name, env_id, config, seed + i) for name in policies for i in range(episodes)]
    results = evaluate(specs, play.workers, play.progress, "benchmark", play.transient_slots)
    out_dir = Path(out_dir)
    write_results(results, out_dir / "episodes.csv")  # the episodes first: a failed summary loses none of them
    summary = summarize(results)
    paired = paired_cost_difference(results, policies[0])
    geometric = paired_cost_geometric(results, policies[0])
    scores = {policy: score for (_, _, policy), score in scores_by_policy(results).items()}
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
    return results, summary


def episode_record(policy: str, seed: int) -> dict[str, Any]:
    """One seeded episode of a README row on the default task: its digest and its control cost."""
    r = run_episode(policy, JOINT, ScenarioConfig(), seed)
    values = [f"{float(x):.10g}" for x in (*(r.stage_costs if r.stage_costs is not None else ()), r.outage_rate,
                                           r.rmse_m)]
    return {"seed": seed, "control_cost": float(f"{r.control_cost:.10g}"),
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
    for policy, env, _ in entries:
        make_policy(policy, config, env_id=env)  # a bad name or a mismatched agent fails before any episode
    results = run_entries(entries, config, range(episodes), play, desc="learned protocol")
    runtime = f" Runtime {time.perf_counter() - start:.0f} s with {play.workers} workers."
    table = learned_table(reduce(results), entries) + runtime
    write_results(results, Path(out_dir) / "episodes.csv")
    (Path(out_dir) / "summary.md").write_text(table + "\n")
    return table


def suite_policies() -> list[str]:
    """The experts, baselines and anchors of :data:`SUITE_POLICIES` (``anchor:hover`` left out: its
    cost is thousands of times the experts') and every shipped agent that acts under the paper's
    control law (not one trained with the delivery law, ``zoo:dv-joint`` and ``zoo:dv-comm``, compared
    on their own tasks in docs/LEARNED.md)."""
    return list(SUITE_POLICIES) + [f"zoo:{n}" for n, rec in zoo_agents().items()
                                   if rec.get("config", {}).get("control", {}).get("law", "paper") == "paper"]


def _applicable(policy: str, env: str, config: ScenarioConfig) -> str | None:
    """None when ``policy`` can act on ``env`` with ``config``, else why not (one line). Names are
    checked on the default task first (by the caller), so a typo is an error, not an n/a."""
    try:
        build_policy(policy, config, env)
    except (ValueError, MissingExtra) as exc:  # a network built for another K; torch not installed
        return str(exc)
    return None


class Suite(NamedTuple):
    """The suite's episodes (``task`` set), the (task, policy) pairs that cannot run with the reason,
    the per-slot mean stage costs (``per_slot.csv``) and the wall time."""

    results: list[EpisodeResult]
    skipped: dict[tuple[str, str], str]
    per_slot: list[dict[str, Any]]
    seconds: float


def run_suite(policies: Sequence[str], tasks: Sequence[str], episodes: int, out_dir: Path, play: Play = DEFAULT_PLAY
              ) -> Suite:
    """Every policy on every task (seeds 0..episodes-1), with the references of each env used and
    the reference rows (:data:`.run.REFERENCE_ROWS`, on ``lawn/Joint-v1``); writes ``episodes.csv``
    and ``per_slot.csv`` (the mean stage cost per slot of every task, env and policy)."""
    start = time.perf_counter()
    policies = list(dict.fromkeys(policies))
    envs = {p: policy_env(p) for p in policies}
    for p in policies:  # unknown names and agents that cannot act on the default task are errors
        build_policy(p, ScenarioConfig(), envs[p])
    results: list[EpisodeResult] = []
    profiles: list[dict[str, Any]] = []
    skipped: dict[tuple[str, str], str] = {}
    for task in tasks:
        config = presets.get(task)
        entries = [Entry(p, env) for env in dict.fromkeys([JOINT, *envs.values()]) for p in (SCORE_HIGH, SCORE_LOW)]
        entries += [Entry(p, JOINT) for p in REFERENCE_ROWS]
        for p in policies:
            reason = _applicable(p, envs[p], config)
            if reason is not None:
                skipped[(task, p)] = reason
            elif (p, envs[p]) not in [e[:2] for e in entries]:
                entries.append(Entry(p, envs[p]))
        results += run_entries(entries, config, range(episodes), play, task=task, desc=f"suite: {task}",
                               profiles=profiles)
    write_results(results, Path(out_dir) / "episodes.csv")
    write_rows(profiles, Path(out_dir) / "per_slot.csv")
    return Suite(results, skipped, profiles, time.perf_counter() - start)


def suite_pages(policies: Sequence[str], tasks: Sequence[str], episodes: int, out: Path, play: Play,
                docs: Path | None = None) -> dict[str, str]:
    """The suite protocol end to end: :func:`run_suite`, its tables (``board``, ``references``,
    ``structure``, ``tasks``) written to ``out/NAME.md`` with ``per_slot.png``, the fleet networks
    among the policies on every fleet size (:func:`fleet_block`, ``fleet``), and with ``docs`` their
    blocks of ``docs/LEADERBOARD.md`` and ``docs/LEARNED.md`` (checked before any episode)."""
    fleet = [p for p in fleet_agents() if p in policies]
    pages = {"LEADERBOARD.md": list(SUITE_BLOCKS.values())}
    if fleet:
        pages["LEARNED.md"] = ["fleet-generalization"]
    for page, names in pages.items() if docs else ():
        path = Path(docs or ".") / page
        missing = [n for n in names if n not in block_names(path.read_text() if path.exists() else "")]
        if missing:
            raise ValueError(f"--docs {docs}: {path} has no generated block {', '.join(missing)}")
    suite = run_suite(policies, tasks, episodes, out, play)
    stats = reduce(suite.results)
    board, refs = suite_table(stats, policies, tasks, suite.skipped)
    reasons = skipped_summary(suite.skipped)
    board += (f"\n\n{len(policies)} policies x {len(tasks)} tasks ({', '.join(tasks)}), test seeds 0-{episodes - 1}, "
              f"{suite.seconds / 60:.1f} min with {play.workers} workers. n/a: the policy cannot act on the task"
              + (": " + "; ".join(reasons) + "." if reasons else ".")
              + " –: no score (the references do not separate on that task's seeds).")
    tables = {"board": board, "references": refs, "structure": structure_table(stats, tasks),
              "tasks": task_tables(stats, policies, tasks, suite.skipped)}
    for name, text in tables.items():
        (out / f"{name}.md").write_text(text + "\n")
    plot_profiles(suite.per_slot, out / "per_slot.png", tasks, play.transient_slots)
    tables["fleet"] = fleet_block(fleet, play, out, episodes) if fleet else ""
    if docs:
        source = f"lawn benchmark --suite --docs {docs}"
        for name, block in SUITE_BLOCKS.items():
            replace_block(docs / "LEADERBOARD.md", block, tables[name], source=source)
        (docs / "figures").mkdir(parents=True, exist_ok=True)
        shutil.copy2(out / "per_slot.png", docs / "figures" / "suite-per-slot.png")
        if fleet:
            replace_block(docs / "LEARNED.md", "fleet-generalization", tables["fleet"], source=source)
    return tables


def fleet_agents() -> list[str]:
    """The shipped agents whose network reads the entity layout (``zoo:NAME``) and was trained on the
    default scenario (not the distilled agents of the steady tasks, :mod:`training.distil`)."""
    distilled = {name for name, r in RECIPES.items() if r.section == "distil"}
    return [f"zoo:{name}" for name, rec in zoo_agents().items()
            if (rec.get("interface") or {}).get("layout") == "entities" and name not in distilled]


def fleet_target(policy: str, k: int, c: RangeComparison) -> str:
    """The verdict of the fleet-size targets (:data:`FLEET_TARGETS`, :data:`FLEET_WORST`) for a network
    trained on mixed fleets (``trainer: fleet``); "–" for the others (the multi-agent ones are trained at
    one K) and the noise floor."""
    record = zoo_agents().get(policy.partition(":")[2]) if policy.startswith("zoo:") else None
    if record is None or record.get("trainer") != "fleet":
        return "–"
    target = FLEET_TARGETS.get(k)
    if target is None:
        return "reported"
    met = c.below(1.0 + target) and c.worst <= FLEET_WORST
    return f"≤ {target * 100:+.0f} %, ≤ {FLEET_WORST:g}×: {'met' if met else 'missed'}"


def run_generalization(agents: Sequence[str], sizes: Mapping[int, int] = FLEET_SIZES, play: Play = FLEET_PLAY,
                       base: ScenarioConfig | None = None) -> list[EpisodeResult]:
    """Full episodes of every agent, the best expert and its noise floor on the default task (or
    ``base``) with each fleet size (``task`` = ``k<K>``), on the first n seeds of both test ranges
    (:func:`.stats.test_seeds`, n per size)."""
    envs = list(dict.fromkeys(policy_env(a) for a in agents))
    noise = next(iter(NOISE))
    results: list[EpisodeResult] = []
    for k, seeds in sizes.items():
        config = (base or presets.get("default")).override(num_agvs=int(k))
        entries = [Entry(p, env) for env in envs for p in (SCORE_HIGH, noise)]
        entries += [Entry(a, policy_env(a)) for a in agents]
        results += run_entries(entries, config, test_seeds(int(seeds)), play, task=f"k{k}",
                               desc=f"fleet sizes: K = {k}")
    return results


def fleet_block(agents: Sequence[str], play: Play, out: Path, cap: int | None = None) -> str:
    """The fleet-size protocol: :func:`run_generalization` of ``agents`` on :data:`FLEET_SIZES` (at most
    ``cap`` seeds per size and range), written to ``out/fleet_sizes.csv`` and ``.md``; returns the block."""
    start = time.perf_counter()
    sizes = {k: min(n, cap) if cap else n for k, n in FLEET_SIZES.items()}
    results = run_generalization(agents, sizes, play)
    seeds = ", ".join(f"K = {k}: {n}" for k, n in sizes.items())
    block = (f"Test seeds S..S+n-1 of each range S = {', '.join(map(str, TEST_RANGES))}, n per fleet size ({seeds}); "
             f"{play.workers} worker processes, {(time.perf_counter() - start) / 60:.1f} min.\n\n"
             + fleet_table(reduce(results), agents, sizes, fleet_target))
    write_results(results, out / "fleet_sizes.csv")
    (out / "fleet_sizes.md").write_text(block + "\n")
    return block


def main(argv: list[str] | None = None) -> int:
    """``python -m training.results.protocols [--write-digests]``: compare the README rows' episodes
    with the recorded ones (exit 1 naming the rows that changed), or record them."""
    parser = argparse.ArgumentParser(prog="python -m training.results.protocols",
                                     description=str(main.__doc__).split(":")[0])
    parser.add_argument("--write-digests", action="store_true", help=f"rewrite {DIGESTS.name}")
    args = parser.parse_args(argv)
    now = digest_records()
    if args.write_digests:
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
