"""``lawn benchmark``: the expert and the baselines on the same seeds, a table and a bar plot;
``--protocol learned``: the learned agents beside their anchors on the 100 test seeds; ``--suite``:
the task suite's leaderboard (normalized scores, :mod:`training.results.stats`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from agents import BENCHMARK_POLICIES
from lawn_env import presets
from lawn_env.presets import SUITE

from ..protocol import TEST_EPISODES
from ..results.episode import Play
from ..results.protocols import (
    FLEET_SIZES,
    execute,
    fleet_agents,
    fleet_protocol,
    learned_protocol,
    run_benchmark,
    suite_pages,
    suite_policies,
)
from ..results.run import REFERENCE_ROWS, build_policy
from ..results.stats import SCORE_HIGH, SCORE_LOW, SCORE_VERSION
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
    if not args.suite and (args.tasks or args.docs):
        raise ValueError("--tasks and --docs belong to --suite (the task suite's leaderboard)")
    if args.sizes and args.protocol != "fleet":
        raise ValueError(f"--sizes {' '.join(map(str, args.sizes))}: fleet sizes belong to --protocol fleet")
    if args.suite or args.protocol != "paper":
        _check_fixed_protocol(args)
        return _suite(args) if args.suite else _learned(args) if args.protocol == "learned" else _fleet(args)
    args.env = args.env or "lawn/Joint-v1"
    args.seed = 0 if args.seed is None else args.seed
    cfg = config_of(args)
    args.policies = list(args.policies or (*BENCHMARK_POLICIES, *REFERENCE_ROWS)) + included(args.include)
    for name in args.policies:
        build_policy(name, cfg, args.env)  # fail fast
    args.episodes = args.episodes or 20
    run_benchmark(args.policies, args.env, cfg, args.episodes, args.seed, Path(args.out), _play(args))
    print(f"lawn benchmark: {args.env}, preset {args.preset}, K={cfg.num_agvs}, {args.episodes} seeds from "
          f"{args.seed}; mean ± 95 % interval")
    print((Path(args.out) / "summary.md").read_text().rstrip())
    print(f"wrote {args.out}/episodes.csv, summary.csv, summary.md, benchmark.png")
    return 0


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


def _play(args: argparse.Namespace) -> Play:
    return Play(args.workers, not args.quiet, args.transient_slots)


def _suite(args: argparse.Namespace) -> int:
    episodes, out = args.episodes or TEST_EPISODES, Path(args.out)
    tasks = args.tasks or list(SUITE)
    policies = list(args.policies or suite_policies()) + included(args.include)
    docs = Path(args.docs) if args.docs else None
    tables = suite_pages(policies, tasks, episodes, out, _play(args), docs)
    print(f"lawn benchmark --suite: {len(policies)} policies x {len(tasks)} tasks, {episodes} seeds each; normalized "
          f"score v{SCORE_VERSION} [95 %] (0 = {SCORE_LOW}, 100 = {SCORE_HIGH})")
    print(tables["board"])
    print(tables["structure"])
    print(f"wrote {out}/episodes.csv, per_slot.csv, board.md (the scores), references.md (the references' costs), "
          "structure.md (cost structure, noise floor, headroom), tasks.md (every row per task) and per_slot.png")
    if tables["fleet"]:
        print(tables["fleet"])
        print(f"wrote {out}/fleet_sizes.csv and fleet_sizes.md (the fleet networks on K = 3 ... 64)")
    if docs:
        print(f"wrote the suite's blocks of {docs}/LEADERBOARD.md" + (" and LEARNED.md" if tables["fleet"] else ""))
    return 0


def _learned(args: argparse.Namespace) -> int:
    episodes, out = args.episodes or TEST_EPISODES, Path(args.out)
    protocol = learned_protocol(list(args.policies or []) + included(args.include), episodes)
    outcome = execute(protocol, _play(args), out)
    print(f"lawn benchmark --protocol learned: test seeds 0-{episodes - 1}, full unmodified episodes")
    print(outcome.tables["summary.md"])
    print(f"wrote {out}/episodes.csv and {out}/summary.md")
    return 0


def _fleet(args: argparse.Namespace) -> int:
    out = Path(args.out)
    agents = list(args.policies or fleet_agents()) + included(args.include)
    if not agents:
        raise ValueError("--protocol fleet: no shipped fleet network; name the networks with --policies (zoo:NAME, "
                         "sb3:DIR of a run whose interface reads the entity layout)")
    sizes = {k: min(FLEET_SIZES.get(k, 20), args.episodes or FLEET_SIZES.get(k, 20))
             for k in (args.sizes or FLEET_SIZES)}
    outcome = execute(fleet_protocol(agents, sizes), _play(args), out)
    print(f"lawn benchmark --protocol fleet: {len(agents)} networks, K = {', '.join(map(str, sizes))}")
    print(outcome.tables["fleet_sizes.md"])
    print(f"wrote {out}/fleet_sizes.csv and {out}/fleet_sizes.md")
    return 0
