"""``lawn benchmark``'s protocols as data: a :class:`Protocol` declares the batches of episodes to
play (:class:`Batch`: a task, its scenario, the rows, the seeds) and the tables to make of their
statistics; :func:`execute` plays any protocol the same way (:mod:`.run`), reduces its results
(:func:`.rows.reduce`), makes its tables (:data:`TABLES`, over :mod:`.report`) and writes them. A new
protocol is a declaration:

* **Paper protocol** (:func:`paper_protocol`, ``lawn benchmark``): the policies on the same seeds of one
  scenario, compared with the first per seed and scored (:mod:`.digests` replays the README's).
* **Learned protocol** (:func:`learned_protocol`, ``--protocol learned``, ``lawn zoo build``): every
  agent on the test seeds beside the best expert, ``epa`` and the zero action of the interface it
  acts through.
* **Task suite** (:func:`suite_protocol`, ``--suite``; :func:`paper.leaderboard.write_suite_pages` writes
  its tables into docs/LEADERBOARD.md):
  experts, baselines, shipped agents and the reference rows on every preset of
  :data:`lawn_env.presets.SUITE`; an agent that cannot act on a task (a network built for K = 4) is
  reported as such.
* **Fleet sizes** (:func:`fleet_protocol`, docs/LEARNED.md): the networks that read the entity layout on
  K = 3..64 AGVs beside the best expert and its noise floor, with their targets (:data:`FLEET_TARGETS`).
  The distilled agents' protocol is declared by :mod:`training.distil`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

from agents import make_policy
from agents.base import JOINT
from agents.errors import MissingExtra
from agents.learned import zoo_agents, zoo_agents_for
from agents.registry import Names
from lawn_env import ScenarioConfig, presets

from .episode import DEFAULT_PLAY, Entry, EpisodeResult, EpisodeSpec, Play, write_results, write_rows
from .report import (
    board_table,
    fleet_table,
    learned_table,
    plot_profiles,
    plot_summary,
    references_table,
    skipped_summary,
    structure_table,
    summary_markdown,
    task_tables,
)
from .rows import Statistics, SummaryRow, reduce
from .run import (
    NOISE,
    REFERENCE_ROWS,
    build_policy,
    evaluate,
    is_reference_row,
    learned_entries,
    per_slot_profile,
    policy_env,
)
from .seeds import TEST_EPISODES, TEST_RANGES, test_seeds
from .stats import SCORE_HIGH, SCORE_LOW, RangeComparison

__all__ = ["Batch", "Protocol", "Outcome", "execute", "TABLES", "FILES", "paper_protocol", "learned_protocol",
           "SUITE_POLICIES", "suite_policies", "suite_protocol", "SUITE_BLOCKS", "FLEET_SIZES",
           "FLEET_TARGETS", "FLEET_WORST", "fleet_agents", "fleet_target", "fleet_protocol"]

#: Experts and baselines of the suite, the registry's entries with ``suite=True`` (global-mpc, seconds per
#: slot, is the gap study's reference), then the anchors.
SUITE_POLICIES = Names("suite", tail=("anchor:stake", "anchor:distance"))
#: Fleet size -> test seeds (0..n-1 of each test range) of the fleet-size table.
FLEET_SIZES: dict[int, int] = {3: 100, 4: 100, 8: 100, 16: 40, 32: 40, 64: 20}
#: The fleet networks' targets against dv-mpc: the upper bound of the geometric interval, per K
#: (None: reported), on every range; and no seed over FLEET_WORST times dv-mpc's cost.
FLEET_TARGETS: dict[int, float | None] = {3: 0.05, 4: 0.05, 8: 0.05, 16: 0.10, 32: 0.10, 64: None}
FLEET_WORST = 3.0
#: The suite's tables: the file each is written to in the output directory, and its block of LEADERBOARD.md.
SUITE_BLOCKS = {"board": "suite-board", "structure": "suite-structure", "tasks": "suite-tasks",
                "references": "suite-references"}


# ---------------------------------------------------------------------- a protocol, played
class Batch(NamedTuple):
    """Episodes of one task: every entry (a policy on its env) on every seed of one scenario. ``task``
    labels the results (None: a paper-protocol run's one scenario, no task column)."""

    task: str | None
    config: ScenarioConfig
    entries: tuple[Entry, ...]
    seeds: tuple[int, ...]


@dataclass(frozen=True)
class Protocol:
    """A protocol as data: its batches, its tables (the output file -> a name of :data:`TABLES`), its
    rows in order (``policies``; the entries' otherwise), the (task, policy) pairs that cannot act
    there with the reason, whether the episodes keep their per-slot costs and whether the mean stage
    cost per slot is written (``per_slot.csv``), its fleet sizes (task ``k<K>`` -> seeds a range), its
    other outputs (the output file -> a name of :data:`FILES`: a CSV, a figure) and the protocols played
    after it into the same directory (``then``: the suite's fleet sizes)."""

    name: str
    batches: tuple[Batch, ...]
    tables: Mapping[str, str]
    policies: tuple[str, ...] = ()
    skipped: Mapping[tuple[str, str], str] = field(default_factory=dict)
    keep_traces: bool = False
    per_slot: bool = False
    sizes: Mapping[int, int] = field(default_factory=dict)
    episodes_file: str = "episodes.csv"
    files: Mapping[str, str] = field(default_factory=dict)
    then: tuple[Protocol, ...] = ()

    def __post_init__(self) -> None:
        unknown = sorted(set(self.tables.values()) - set(TABLES))
        if unknown:  # before any episode is played
            raise ValueError(f"Protocol {self.name!r}: unknown tables {unknown}; valid: {', '.join(TABLES)}")
        unknown = sorted(set(self.files.values()) - set(FILES))
        if unknown:
            raise ValueError(f"Protocol {self.name!r}: unknown files {unknown}; valid: {', '.join(FILES)}")

    @property
    def tasks(self) -> list[str]:
        return list(dict.fromkeys(b.task or "default" for b in self.batches))

    @property
    def entries(self) -> list[Entry]:
        """Every entry (policy, env) once, in the batches' order."""
        seen: dict[tuple[str, str], Entry] = {}
        for b in self.batches:
            for e in b.entries:
                seen.setdefault((e.policy, e.env), e)
        return list(seen.values())


class Outcome(NamedTuple):
    """A protocol played: its results, their statistics, its tables (file -> Markdown), the mean stage
    cost per slot (when asked for) and the wall time."""

    results: list[EpisodeResult]
    stats: Statistics
    tables: dict[str, str]
    per_slot: list[dict[str, str | int | float]]
    seconds: float


def execute(protocol: Protocol, play: Play = DEFAULT_PLAY, out: Path | None = None) -> Outcome:
    """Play every batch of ``protocol`` (every entry on every seed), reduce the results, make its
    tables and, with ``out``, write the episodes (first: a failed table loses none of them), the
    per-slot means, each table and each file to ``out``; then the protocols of ``protocol.then``, whose
    tables join the outcome's."""
    start = time.perf_counter()
    results: list[EpisodeResult] = []
    for b in protocol.batches:
        specs = [EpisodeSpec(e.policy, e.env, b.config, int(s)) for e in b.entries for s in b.seeds]
        desc = protocol.name + (f": {b.task}" if b.task else "")
        results += [r.with_(task=b.task) for r in evaluate(specs, play.workers, play.progress, desc,
                                                            play.transient_slots)]
    per_slot = per_slot_profile(results) if protocol.per_slot else []
    if not protocol.keep_traces:
        results = [r.with_(stage_costs=None) for r in results]
    if out is not None:
        write_results(results, Path(out) / protocol.episodes_file)
        if protocol.per_slot:
            write_rows(per_slot, Path(out) / "per_slot.csv")
    stats, seconds = reduce(results), time.perf_counter() - start
    tables = {file: TABLES[name](protocol, stats, seconds, play) for file, name in protocol.tables.items()}
    outcome = Outcome(results, stats, tables, per_slot, seconds)
    if out is not None:
        for file, text in tables.items():
            (Path(out) / file).write_text(text + ("" if text.endswith("\n") else "\n"))
        for file, name in protocol.files.items():
            FILES[name](protocol, outcome, Path(out) / file, play)
    for part in protocol.then:
        tables.update(execute(part, play, out).tables)
    return outcome


# ---------------------------------------------------------------------- the tables of the protocols
def _summary_rows(protocol: Protocol, stats: Statistics) -> list[SummaryRow]:
    """The paper protocol's summary (every metric's mean and interval per policy) with each policy
    against the first: the paired mean, the geometric mean of the ratios, the seeds won, the score."""
    batch = protocol.batches[0]
    return stats.summary(batch.entries[0].env, protocol.policies, batch.task or "default", protocol.policies[0])


def _summary(protocol: Protocol, stats: Statistics, seconds: float, play: Play) -> str:
    return summary_markdown(_summary_rows(protocol, stats))


def _learned(protocol: Protocol, stats: Statistics, seconds: float, play: Play) -> str:
    return (learned_table(stats, protocol.entries)
            + f" Runtime {seconds:.0f} s with {play.workers} workers.")


def _board_rows(policies: Sequence[str]) -> list[Entry]:
    """The board's rows: the policies on their envs, the reference rows (on ``lawn/Joint-v1``) after
    the best expert."""
    at = list(policies).index(SCORE_HIGH) + 1 if SCORE_HIGH in policies else 0
    names = list(dict.fromkeys([*policies[:at], *REFERENCE_ROWS, *policies[at:]]))
    return [Entry(p, JOINT if is_reference_row(p) else policy_env(p)) for p in names]


def _board(protocol: Protocol, stats: Statistics, seconds: float, play: Play) -> str:
    tasks, reasons = protocol.tasks, skipped_summary(protocol.skipped)
    seeds = protocol.batches[0].seeds
    return (board_table(stats, _board_rows(protocol.policies), tasks, protocol.skipped)
            + f"\n\n{len(protocol.policies)} policies x {len(tasks)} tasks ({', '.join(tasks)}), test seeds "
            f"{seeds[0]}-{seeds[-1]}, {seconds / 60:.1f} min with {play.workers} workers. n/a: the policy cannot act "
            "on the task" + (": " + "; ".join(reasons) + "." if reasons else ".")
            + " –: no score (the references do not separate on that task's seeds).")


def _fleet(protocol: Protocol, stats: Statistics, seconds: float, play: Play) -> str:
    per_size = ", ".join(f"K = {k}: {n}" for k, n in protocol.sizes.items())
    return (f"Test seeds S..S+n-1 of each range S = {', '.join(map(str, TEST_RANGES))}, n per fleet size "
            f"({per_size}); {play.workers} worker processes, {seconds / 60:.1f} min.\n\n"
            + fleet_table(stats, [Entry(a, policy_env(a)) for a in protocol.policies], protocol.sizes, fleet_target))


#: Table name -> its maker (the protocol, its statistics, the wall time, how it was played).
TABLES: dict[str, Callable[[Protocol, Statistics, float, Play], str]] = {
    "summary": _summary,
    "learned": _learned,
    "board": _board,
    "references": lambda p, s, t, play: references_table(s, p.tasks),
    "structure": lambda p, s, t, play: structure_table(s, p.tasks, REFERENCE_ROWS),
    "tasks": lambda p, s, t, play: task_tables(s, list(dict.fromkeys([SCORE_HIGH, SCORE_LOW, *REFERENCE_ROWS,
                                                                       *p.policies])), p.tasks, p.skipped),
    "fleet": _fleet,
}


def _summary_csv(protocol: Protocol, outcome: Outcome, path: Path, play: Play) -> None:
    write_rows([row.as_row() for row in _summary_rows(protocol, outcome.stats)], path)


def _summary_plot(protocol: Protocol, outcome: Outcome, path: Path, play: Play) -> None:
    batch = protocol.batches[0]
    title = (f"{batch.entries[0].env}, K={batch.config.num_agvs}, {len(batch.seeds)} seeds from {batch.seeds[0]}: "
             "mean ± 95 % interval")
    plot_summary(_summary_rows(protocol, outcome.stats), path, title=title)


def _profiles_plot(protocol: Protocol, outcome: Outcome, path: Path, play: Play) -> None:
    plot_profiles(outcome.per_slot, path, protocol.tasks, play.transient_slots)


#: File maker name -> its writer (the protocol, its outcome, the path, how it was played).
FILES: dict[str, Callable[[Protocol, Outcome, Path, Play], None]] = {
    "summary-csv": _summary_csv,
    "summary-plot": _summary_plot,
    "profiles-plot": _profiles_plot,
}


# ---------------------------------------------------------------------- the paper protocol
def paper_protocol(policies: Sequence[str], env_id: str, config: ScenarioConfig, episodes: int, seed: int
                   ) -> Protocol:
    """Every policy on seeds ``seed .. seed+episodes-1`` of one scenario on ``env_id``, compared with
    the first, the episodes with their per-slot costs: ``episodes.csv``, ``summary.md`` (with ``epa``
    and ``dv-mpc`` among the policies, the normalized score; every policy against the first per seed,
    as a mean of relative differences and as a geometric mean of cost ratios, the deciding statistic,
    docs/benchmark.md), ``summary.csv`` and ``benchmark.png``. Every policy is built once here: a bad
    name or one that cannot act on ``env_id`` fails before any episode."""
    for name in policies:
        build_policy(name, config, env_id)
    batch = Batch(None, config, tuple(Entry(p, env_id) for p in policies), tuple(range(seed, seed + episodes)))
    return Protocol("benchmark", (batch,), {"summary.md": "summary"}, policies=tuple(policies), keep_traces=True,
                    files={"summary.csv": "summary-csv", "benchmark.png": "summary-plot"})


# ---------------------------------------------------------------------- the learned protocol
def learned_protocol(agents: Sequence[str], episodes: int = TEST_EPISODES, config: ScenarioConfig | None = None
                     ) -> Protocol:
    """Every agent of ``agents`` (default: the shipped ones that act on ``config``, ``zoo_agents_for``) on test
    seeds 0..episodes-1 beside the best expert, ``epa`` and its own anchor; a bad or mismatched agent fails here."""
    config = config or ScenarioConfig()
    entries = learned_entries(list(agents) or zoo_agents_for(config))
    for policy, env, _ in entries:  # an agent trained elsewhere: agents.learned.check_scenario's refusal
        try:
            make_policy(policy, config, env_id=env)
        except ValueError as exc:  # noqa: PERF203 - once per agent, before any episode
            raise ValueError(f"{exc}; the learned protocol plays one scenario, the default (lawn benchmark --env "
                             f"{env} --policies {policy} with that setting plays the agent on its own)") from None
    return Protocol("learned protocol", (Batch("default", config, tuple(entries), tuple(range(episodes))),),
                    {"summary.md": "learned"})


# ---------------------------------------------------------------------- the task suite
def suite_policies() -> list[str]:
    """The experts, baselines and anchors of :data:`SUITE_POLICIES` (``anchor:hover`` left out: its cost is
    thousands of times the experts') and every shipped agent that acts on the default scenario (not
    ``zoo:dv-joint`` and ``zoo:dv-comm``, trained under the delivery law: docs/LEARNED.md compares them)."""
    return list(SUITE_POLICIES) + zoo_agents_for(ScenarioConfig())


def _applicable(policy: str, env: str, config: ScenarioConfig) -> str | None:
    """None when ``policy`` can act on ``env`` with ``config``, else why not (one line). Names are
    checked on the default task first (by the caller), so a typo is an error, not an n/a."""
    try:
        build_policy(policy, config, env)
    except (ValueError, MissingExtra) as exc:  # a network built for another K; torch not installed
        return str(exc)
    return None


def suite_protocol(policies: Sequence[str], tasks: Sequence[str], episodes: int) -> Protocol:
    """Every policy on every task (seeds 0..episodes-1), with the references of each env used and the
    reference rows (on ``lawn/Joint-v1``): the board, the references, the cost structure and the
    per-task tables (:data:`SUITE_BLOCKS`), the episodes without their per-slot costs but their mean per
    slot (``per_slot.csv``, ``per_slot.png``); then the fleet networks among the policies on every fleet
    size (:func:`fleet_protocol`, ``fleet_sizes.csv`` and ``.md``; ``episodes`` caps the seeds per size).
    Both are declared, and checked, before any episode."""
    policies = list(dict.fromkeys(policies))
    envs = {p: policy_env(p) for p in policies}
    for p in policies:  # unknown names and agents that cannot act on the default task are errors
        build_policy(p, ScenarioConfig(), envs[p])
    batches, skipped = [], {}
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
        batches.append(Batch(task, config, tuple(entries), tuple(range(episodes))))
    tables = {f"{name}.md": name for name in SUITE_BLOCKS}
    fleet = [p for p in fleet_agents() if p in policies]
    sized = (fleet_protocol(fleet, {k: min(n, episodes) for k, n in FLEET_SIZES.items()}),) if fleet else ()
    return Protocol("suite", tuple(batches), tables, tuple(policies), skipped, per_slot=True,
                    files={"per_slot.png": "profiles-plot"}, then=sized)


# ---------------------------------------------------------------------- the fleet sizes
def fleet_agents() -> list[str]:
    """The shipped agents whose network reads the entity layout (``zoo:NAME``) and that act on the
    default scenario (not the distilled agents, trained under the delivery law of the steady tasks:
    :func:`agents.learned.zoo_agents_for` leaves them out)."""
    default = set(zoo_agents_for(ScenarioConfig()))
    return [f"zoo:{name}" for name, rec in zoo_agents().items()
            if rec.layout == "entities" and f"zoo:{name}" in default]


def fleet_target(policy: str, k: int, c: RangeComparison) -> str:
    """The verdict of the fleet-size targets (:data:`FLEET_TARGETS`, :data:`FLEET_WORST`) for a network
    trained on mixed fleets (``trainer: fleet``); "–" for the others (the multi-agent ones are trained at
    one K) and the noise floor."""
    record = zoo_agents().get(policy.partition(":")[2]) if policy.startswith("zoo:") else None
    if record is None or record.trainer != "fleet":
        return "–"
    target = FLEET_TARGETS.get(k)
    if target is None:
        return "reported"
    met = c.below(1.0 + target) and c.worst <= FLEET_WORST
    return f"≤ {target * 100:+.0f} %, ≤ {FLEET_WORST:g}×: {'met' if met else 'missed'}"


def fleet_protocol(agents: Sequence[str], sizes: Mapping[int, int] = FLEET_SIZES, base: ScenarioConfig | None = None
                   ) -> Protocol:
    """Every agent, the best expert and its noise floor on the default task (or ``base``) with each fleet
    size (task ``k<K>``), on the first n seeds of both test ranges (n per size): ``fleet_sizes.csv`` and
    the table with the targets (``fleet_sizes.md``). An agent that cannot act at a size fails here."""
    envs = list(dict.fromkeys(policy_env(a) for a in agents))
    noise = next(iter(NOISE))
    batches = []
    for k, seeds in sizes.items():
        config = (base or presets.get("default")).override(num_agvs=int(k))
        for a in agents:
            if (reason := _applicable(a, policy_env(a), config)) is not None:
                raise ValueError(f"{a} cannot act with {k} AGVs (the fleet sizes need a network that reads the "
                                 f"entity layout): {reason}")
        entries = [Entry(p, env) for env in envs for p in (SCORE_HIGH, noise)]
        entries += [Entry(a, policy_env(a)) for a in agents]
        batches.append(Batch(f"k{k}", config, tuple(entries), tuple(test_seeds(int(seeds)))))
    return Protocol("fleet sizes", tuple(batches), {"fleet_sizes.md": "fleet"}, tuple(agents), sizes=dict(sizes),
                    episodes_file="fleet_sizes.csv")
