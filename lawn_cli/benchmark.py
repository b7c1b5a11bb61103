"""``lawn benchmark``: the expert and the baselines on the same seeds, a table and a bar plot;
``--protocol learned``: the learned agents beside their anchors on the 100 test seeds; ``--suite``:
the task suite's leaderboard (normalized scores, :mod:`evaluation.stats`)."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path

from agents import BENCHMARK_POLICIES
from evaluation.episode import Play
from evaluation.protocols import (
    FLEET_SIZES,
    Protocol,
    execute,
    fleet_agents,
    fleet_protocol,
    learned_protocol,
    paper_protocol,
    suite_policies,
    suite_protocol,
)
from evaluation.run import REFERENCE_ROWS
from evaluation.seeds import TEST_EPISODES
from evaluation.stats import SCORE_HIGH, SCORE_LOW, SCORE_VERSION
from lawn_env import presets
from lawn_env.presets import SUITE
from paper.leaderboard import check_suite_pages, write_suite_pages

from .common import command, comparison_env, config_of, count, included, policy_help, policy_name


def add(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> argparse.ArgumentParser:
    bm = command(sub, "benchmark", "workers", "quiet", "seed", "config", "split", "overwrite",
                 epilog="--protocol learned and --suite fix the test seeds (0..N-1) and the scenario; "
                        "--seed, --preset, --set and --env belong to the paper protocol.")
    bm.add_argument("--policies", nargs="+", default=None, type=policy_name,
                    help=policy_help() + f" (default: {' '.join(BENCHMARK_POLICIES)} and the reference rows "
                         f"{' '.join(REFERENCE_ROWS)}; with --protocol learned every "
                         "shipped agent with its anchor and the references; with --suite every expert, baseline, "
                         "shipped agent and the stake and distance anchors, beside the reference rows)")
    bm.add_argument("--protocol", choices=["paper", "learned", "fleet"], default="paper",
                    help="paper (default): the policies on --episodes seeds of one scenario; learned: agents beside "
                         "the best expert, epa and their own anchors on the 100 test seeds, with the normalized score; "
                         "fleet: networks that read the entity layout (default: the shipped ones) beside dv-mpc and "
                         "its noise floor with each fleet size of --sizes, on both test ranges")
    bm.add_argument("--sizes", nargs="+", type=count, default=None, metavar="K",
                    help="--protocol fleet: the fleet sizes (default: 3 4 8 16 32 64, with 100, 100, 100, 40, 40 "
                         "and 20 seeds per test range; --episodes caps them)")
    bm.add_argument("--suite", action="store_true",
                    help="the task suite (lawn_env.presets.SUITE): normalized score of every policy on every task")
    bm.add_argument("--tasks", nargs="+", default=None, choices=presets.names(), metavar="TASK",
                    help="--suite: only these tasks (presets)")
    bm.add_argument("--docs", default=None, metavar="DIR", help="--suite: also write DIR/LEADERBOARD.md")
    bm.add_argument("--env", default=None, type=comparison_env, metavar="ENV",
                    help="the env of every policy (default: lawn/Joint-v1; --protocol learned and --suite run each "
                         "policy on its own env)")
    bm.add_argument("--include", nargs="*", default=[], metavar="DIR",
                    help="trained run directories (lawn train) to add to the comparison")
    bm.add_argument("--episodes", type=count, default=None,
                    help="seeds from --seed (default: 20; 100 test seeds for --protocol learned and --suite)")
    bm.add_argument("--out", default=None,
                    help="output directory (default: runs/benchmark-MODE, MODE paper, learned, suite or fleet, or "
                         "runs/benchmark-MODE-2, ... when an earlier run's results are there; runs/benchmark is the "
                         "main job's, scripts/run.sh)")
    bm.set_defaults(seed=None, default_out=default_out)  # seed None: the paper protocol's 0, refused by the others
    return bm


def default_out(args: argparse.Namespace) -> Path:
    """Where ``lawn benchmark`` writes without ``--out``: ``runs/benchmark-MODE`` (never the main job's
    ``runs/benchmark``)."""
    return Path("runs") / f"benchmark-{'suite' if args.suite else args.protocol}"


def run(args: argparse.Namespace) -> int:
    """Every mode the same way: its protocol declared (every name, agent and docs page checked before any
    episode), played once (:func:`evaluation.protocols.execute`), its tables printed, and with ``--docs``
    the suite's pages written (:mod:`paper.leaderboard`)."""
    if not args.suite and (args.tasks or args.docs):
        raise ValueError("--tasks and --docs belong to --suite (the task suite's leaderboard)")
    if args.sizes and args.protocol != "fleet":
        raise ValueError(f"--sizes {' '.join(map(str, args.sizes))}: fleet sizes belong to --protocol fleet")
    mode = "suite" if args.suite else args.protocol
    if mode != "paper":
        _check_fixed_protocol(args)
    protocol, head = PROTOCOLS[mode](args)
    docs = Path(args.docs) if args.docs else None
    if docs is not None:
        check_suite_pages(protocol, docs)
    out = Path(args.out)
    outcome = execute(protocol, Play(args.workers, not args.quiet, args.transient_slots), out)
    print(head)
    for file in PRINTED[mode]:
        if file in outcome.tables:
            print(outcome.tables[file].rstrip())
    print(f"wrote {out}/: {', '.join(_written(protocol))}")
    if docs is not None:
        write_suite_pages(protocol, outcome.tables, out, docs)
        print(f"wrote the suite's blocks of {docs}/LEADERBOARD.md" + (" and LEARNED.md" if protocol.then else ""))
    return 0


def _written(protocol: Protocol) -> list[str]:
    """The files a protocol's run writes, in the order it writes them."""
    files = [protocol.episodes_file, *(["per_slot.csv"] if protocol.per_slot else []), *protocol.tables,
             *protocol.files]
    return files + [f for part in protocol.then for f in _written(part)]


def _paper(args: argparse.Namespace) -> tuple[Protocol, str]:
    args.env = args.env or "lawn/Joint-v1"
    args.seed = 0 if args.seed is None else args.seed
    cfg = config_of(args)
    policies = list(args.policies or (*BENCHMARK_POLICIES, *REFERENCE_ROWS)) + included(args.include)
    episodes = args.episodes or 20
    return (paper_protocol(policies, args.env, cfg, episodes, args.seed),
            (f"lawn benchmark: {args.env}, preset {args.preset}, K={cfg.num_agvs}, {episodes} seeds from "
             f"{args.seed}; mean ± 95 % interval"))


def _check_fixed_protocol(args: argparse.Namespace) -> None:
    """``--protocol learned``, ``--protocol fleet`` and ``--suite`` fix the scenario, the seeds and each
    policy's env."""
    mode = "--suite" if args.suite else f"--protocol {args.protocol}"
    if args.suite and args.protocol != "paper":
        raise ValueError(f"--suite and --protocol {args.protocol} are two protocols: give one (the suite already "
                         "runs the shipped agents on the 100 test seeds of every task, the fleet networks on every "
                         "size)")
    if args.preset != "default" or args.set:
        hint = "choose tasks with --tasks" if args.suite else "it runs the default task; --suite runs the other tasks"
        raise ValueError(f"{mode} fixes the scenario: drop --preset {args.preset} / --set ({hint})")
    if args.seed is not None:
        raise ValueError(f"--seed {args.seed}: {mode} fixes the test seeds (0 to --episodes - 1; validation and "
                         "training seeds are disjoint from them)")
    if args.env is not None:
        raise ValueError(f"--env {args.env}: {mode} runs each policy on its own env (a learned agent on the env it "
                         "was trained on, experts, baselines and anchors on lawn/Joint-v1)")


def _suite(args: argparse.Namespace) -> tuple[Protocol, str]:
    episodes = args.episodes or TEST_EPISODES
    tasks = args.tasks or list(SUITE)
    policies = list(args.policies or suite_policies()) + included(args.include)
    return (suite_protocol(policies, tasks, episodes),
            (f"lawn benchmark --suite: {len(policies)} policies x {len(tasks)} tasks, {episodes} seeds each; "
             f"normalized score v{SCORE_VERSION} [95 %] (0 = {SCORE_LOW}, 100 = {SCORE_HIGH})"))


def _learned(args: argparse.Namespace) -> tuple[Protocol, str]:
    episodes = args.episodes or TEST_EPISODES
    return (learned_protocol(list(args.policies or []) + included(args.include), episodes),
            f"lawn benchmark --protocol learned: test seeds 0-{episodes - 1}, full unmodified episodes")


def _fleet(args: argparse.Namespace) -> tuple[Protocol, str]:
    agents = list(args.policies or fleet_agents()) + included(args.include)
    if not agents:
        raise ValueError("--protocol fleet: no shipped fleet network; name the networks with --policies (zoo:NAME, "
                         "sb3:DIR of a run whose interface reads the entity layout)")
    sizes = {k: min(FLEET_SIZES.get(k, 20), args.episodes or FLEET_SIZES.get(k, 20))
             for k in (args.sizes or FLEET_SIZES)}
    return (fleet_protocol(agents, sizes),
            f"lawn benchmark --protocol fleet: {len(agents)} networks, K = {', '.join(map(str, sizes))}")


#: Each mode's protocol from the arguments, and the heading printed above its tables.
PROTOCOLS: dict[str, Callable[[argparse.Namespace], tuple[Protocol, str]]] = {
    "paper": _paper, "learned": _learned, "fleet": _fleet, "suite": _suite}
#: The tables each mode prints (those its run made).
PRINTED = {"paper": ["summary.md"], "learned": ["summary.md"], "fleet": ["fleet_sizes.md"],
           "suite": ["board.md", "structure.md", "fleet_sizes.md"]}
