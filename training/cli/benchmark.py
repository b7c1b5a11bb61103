"""``lawn benchmark``: the expert and the baselines on the same seeds, a table and a bar plot;
``--protocol learned``: the learned agents beside their anchors on the 100 test seeds; ``--suite``:
the task suite's leaderboard (normalized scores, :mod:`training.score`)."""

from __future__ import annotations

import argparse
from pathlib import Path

import lawn_env
from lawn_env import presets

from . import COMMAND_HELP
from .common import Parents, comparison_env, config_of, count, included, policy_help, policy_name


def add(sub: argparse._SubParsersAction, p: Parents) -> None:
    from agents import BENCHMARK_POLICIES

    from ..limits import REFERENCE_ROWS

    bm = sub.add_parser("benchmark", parents=p("workers", "quiet", "seed", "config", "split"),
                        help=COMMAND_HELP["benchmark"],
                        epilog="--protocol learned and --suite fix the test seeds (0..N-1) and the scenario; "
                               "--seed, --preset, --set and --env belong to the paper protocol.")
    bm.add_argument("--policies", nargs="+", default=None, type=policy_name,
                    help=policy_help() + f" (default: {' '.join(BENCHMARK_POLICIES)} and the reference rows "
                         f"{' '.join(REFERENCE_ROWS)}; with --protocol learned every "
                         "shipped agent with its anchor and the references; with --suite every expert, baseline, "
                         "shipped agent and the stake and distance anchors, beside the reference rows)")
    bm.add_argument("--protocol", choices=["paper", "learned"], default="paper",
                    help="paper (default): the policies on --episodes seeds of one scenario; learned: agents "
                         "beside the best expert, epa and their own anchors on the 100 test seeds, with the normalized score")
    bm.add_argument("--suite", action="store_true",
                    help="the task suite (lawn_env.presets.SUITE): normalized score of every policy on every task")
    bm.add_argument("--tasks", nargs="+", default=None, choices=presets.names(), metavar="TASK",
                    help="--suite: only these tasks (presets)")
    bm.add_argument("--docs", default=None, metavar="DIR", help="--suite: also write DIR/LEADERBOARD.md")
    bm.add_argument("--env", default=None, type=comparison_env, metavar="ENV",
                    help="the env of every policy (default: lawn/Joint-v0; --protocol learned and --suite run each "
                         "policy on its own env)")
    bm.add_argument("--include", nargs="*", default=[], metavar="DIR",
                    help="trained run directories (lawn train) to add to the comparison")
    bm.add_argument("--episodes", type=count, default=None,
                    help="seeds from --seed (default: 20; 100 test seeds for --protocol learned and --suite)")
    bm.add_argument("--out", default="runs/benchmark", help="output directory (default: %(default)s)")
    bm.set_defaults(func=run, seed=None)  # None: the paper protocol's 0, refused by the other protocols


def run(args: argparse.Namespace) -> int:
    from agents import BENCHMARK_POLICIES

    from ..benchmark import run_benchmark
    from ..evaluate import build_policy
    from ..limits import REFERENCE_ROWS

    if not args.suite and (args.tasks or args.docs):
        raise ValueError("--tasks and --docs belong to --suite (the task suite's leaderboard)")
    if args.suite or args.protocol == "learned":
        _check_fixed_protocol(args)
        return _suite(args) if args.suite else _learned(args)
    args.env = args.env or "lawn/Joint-v0"
    args.seed = 0 if args.seed is None else args.seed
    cfg = config_of(args)
    args.policies = list(args.policies or (*BENCHMARK_POLICIES, *REFERENCE_ROWS)) + included(args.include)
    for name in args.policies:
        build_policy(name, cfg, args.env)  # fail fast
    args.episodes = args.episodes or 20
    run_benchmark(args.policies, args.env, cfg, args.episodes, args.seed, Path(args.out), workers=args.workers,
                  progress=not args.quiet, transient_slots=args.transient_slots)
    print(f"lawn benchmark: {args.env}, preset {args.preset}, K={cfg.num_agvs}, {args.episodes} seeds from "
          f"{args.seed}; mean ± 95 % interval")
    print((Path(args.out) / "summary.md").read_text().rstrip())
    print(f"wrote {args.out}/episodes.csv, summary.csv, summary.md, benchmark.png")
    return 0


def _check_fixed_protocol(args: argparse.Namespace) -> None:
    """``--protocol learned`` and ``--suite`` fix the scenario, the seeds and each policy's env."""
    mode = "--suite" if args.suite else "--protocol learned"
    if args.suite and args.protocol == "learned":
        raise ValueError("--suite and --protocol learned are two protocols: give one (the suite already runs the "
                         "shipped agents on the 100 test seeds of every task)")
    if args.preset != "default" or args.set:
        hint = "choose tasks with --tasks" if args.suite else "it runs the default task; --suite runs the other tasks"
        raise ValueError(f"{mode} fixes the scenario: drop --preset {args.preset} / --set ({hint})")
    if args.seed is not None:
        raise ValueError(f"--seed {args.seed}: {mode} fixes the test seeds (0 to --episodes - 1; validation and "
                         "training seeds are disjoint from them)")
    if args.env is not None:
        raise ValueError(f"--env {args.env}: {mode} runs each policy on its own env (a learned agent on the env it "
                         "was trained on, experts, baselines and anchors on lawn/Joint-v0)")


def _suite(args: argparse.Namespace) -> int:
    from lawn_env.presets import SUITE

    from ..generalization import fleet_agents
    from ..readme import block_names, replace_block
    from ..suite import (plot_profiles, run_suite, skipped_summary, structure_table, suite_policies,
                               suite_table, task_tables, write_leaderboard)
    from ..protocol import TEST_EPISODES
    from ..score import SCORE_HIGH, SCORE_LOW, SCORE_VERSION
    from ..tables import read_csv

    episodes, out = args.episodes or TEST_EPISODES, Path(args.out)
    tasks = args.tasks or list(SUITE)
    policies = list(args.policies or suite_policies()) + included(args.include)
    learned = Path(args.docs or ".") / "LEARNED.md"
    if args.docs and set(fleet_agents()) & set(policies) and \
            "fleet-generalization" not in block_names(learned.read_text() if learned.exists() else ""):
        raise ValueError(f"--docs {args.docs}: {learned} has no generated block 'fleet-generalization' for the "
                         "fleet networks' table over fleet sizes")
    rows, skipped, seconds = run_suite(policies, tasks, episodes, out, workers=args.workers, progress=not args.quiet,
                                       transient_slots=args.transient_slots)
    board, refs = suite_table(rows, policies, tasks, skipped)
    structure, details = structure_table(rows, tasks), task_tables(rows, policies, tasks, skipped)
    print(f"lawn benchmark --suite: {len(policies)} policies x {len(tasks)} tasks, {episodes} seeds each, "
          f"{seconds / 60:.1f} min; normalized score v{SCORE_VERSION} [95 %] (0 = {SCORE_LOW}, 100 = {SCORE_HIGH})")
    print(board)
    print(structure)
    for line in skipped_summary(skipped):
        print(f"  n/a {line}")
    for name, text in (("board", board), ("references", refs), ("structure", structure), ("tasks", details)):
        (out / f"{name}.md").write_text(text + "\n")
    plot_profiles(read_csv(out / "per_slot.csv"), out / "per_slot.png", tasks, args.transient_slots)
    print(f"wrote {out}/episodes.csv, per_slot.csv, board.md (the scores), references.md (the references' costs), "
          "structure.md (cost structure, noise floor, headroom), tasks.md (every row per task) and per_slot.png")
    fleet = _fleet_sizes(args, policies, out)
    if args.docs:
        figure = plot_profiles(read_csv(out / "per_slot.csv"), Path(args.docs) / "figures" / "suite-per-slot.png", tasks,
                               args.transient_slots)
        doc = write_leaderboard(Path(args.docs) / "LEADERBOARD.md", board, refs, skipped, episodes, seconds,
                                args.workers, tasks, structure=structure, details=details, figure=figure,
                                transient_slots=args.transient_slots)
        print(f"wrote {doc} and {figure}")
        if fleet:
            replace_block(learned, "fleet-generalization", fleet, source="lawn benchmark --suite --docs docs")
            print(f"wrote {learned} (the fleet networks on K = 3 ... 64)")
    return 0


def _fleet_sizes(args: argparse.Namespace, policies: list[str], out: Path) -> str:
    """The fleet networks among ``policies`` on every fleet size of the generalization table
    (:mod:`training.generalization`; ``--episodes`` caps its seeds per size); writes
    ``fleet_sizes.csv`` and ``.md``, returns the block (empty without fleet networks)."""
    import time

    from ..evaluate import write_rows
    from ..generalization import FLEET_SIZES, fleet_agents, generalization_block, run_generalization

    agents = [p for p in fleet_agents() if p in policies]
    if not agents:
        return ""
    start = time.perf_counter()
    sizes = {k: min(n, args.episodes) if args.episodes else n for k, n in FLEET_SIZES.items()}
    rows = run_generalization(agents, sizes, workers=args.workers, progress=not args.quiet)
    block = generalization_block(rows, agents, (time.perf_counter() - start) / 60, args.workers, sizes)
    write_rows(rows, out / "fleet_sizes.csv")
    (out / "fleet_sizes.md").write_text(block + "\n")
    print(block)
    print(f"wrote {out}/fleet_sizes.csv and fleet_sizes.md (the fleet networks on K = 3 ... 64)")
    return block


def _learned(args: argparse.Namespace) -> int:
    from ..leaderboard import run_learned_protocol
    from ..protocol import TEST_EPISODES

    episodes, out = args.episodes or TEST_EPISODES, Path(args.out)
    table = run_learned_protocol(list(args.policies or []) + included(args.include), out, episodes,
                                 workers=args.workers, progress=not args.quiet, transient_slots=args.transient_slots)
    print(f"lawn benchmark --protocol learned: test seeds 0-{episodes - 1}, full unmodified episodes")
    print(table)
    print(f"wrote {out}/episodes.csv and {out}/summary.md")
    return 0
