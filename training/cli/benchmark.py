"""``lawn benchmark``: the expert and the baselines on the same seeds, a table and a bar plot;
``--protocol learned``: the learned agents beside their anchors on the 100 test seeds; ``--suite``:
the task suite's leaderboard (normalized scores, :mod:`training.results.stats`)."""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

from agents import BENCHMARK_POLICIES
from agents.learned import zoo_agents
from lawn_env import presets
from lawn_env.presets import SUITE

from ..benchmark import (
    FLEET_SIZES,
    fleet_agents,
    run_benchmark,
    run_generalization,
    run_learned_protocol,
    run_suite,
    suite_policies,
)
from ..pages import block_names, replace_block
from ..protocol import TEST_EPISODES
from ..results.ranges import TEST_RANGES, fleet_table
from ..results.report import plot_profiles, skipped_summary, structure_table, suite_table, task_tables
from ..results.run import REFERENCE_ROWS, Play, build_policy, read_csv, write_rows
from ..results.stats import SCORE_HIGH, SCORE_LOW, SCORE_VERSION
from .common import command, comparison_env, config_of, count, included, policy_help, policy_name


def add(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> argparse.ArgumentParser:
    bm = command(sub, "benchmark", "workers", "quiet", "seed", "config", "split",
                 epilog="--protocol learned and --suite fix the test seeds (0..N-1) and the scenario; "
                        "--seed, --preset, --set and --env belong to the paper protocol.")
    bm.add_argument("--policies", nargs="+", default=None, type=policy_name,
                    help=policy_help() + f" (default: {' '.join(BENCHMARK_POLICIES)} and the reference rows "
                         f"{' '.join(REFERENCE_ROWS)}; with --protocol learned every "
                         "shipped agent with its anchor and the references; with --suite every expert, baseline, "
                         "shipped agent and the stake and distance anchors, beside the reference rows)")
    bm.add_argument("--protocol", choices=["paper", "learned"], default="paper",
                    help="paper (default): the policies on --episodes seeds of one scenario; learned: agents beside "
                         "the best expert, epa and their own anchors on the 100 test seeds, with the normalized score")
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
    bm.add_argument("--out", default="runs/benchmark", help="output directory (default: %(default)s)")
    bm.set_defaults(seed=None)  # None: the paper protocol's 0, refused by the other protocols
    return bm


def run(args: argparse.Namespace) -> int:
    if not args.suite and (args.tasks or args.docs):
        raise ValueError("--tasks and --docs belong to --suite (the task suite's leaderboard)")
    if args.suite or args.protocol == "learned":
        _check_fixed_protocol(args)
        return _suite(args) if args.suite else _learned(args)
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
                         "was trained on, experts, baselines and anchors on lawn/Joint-v1)")


def _play(args: argparse.Namespace) -> Play:
    return Play(args.workers, not args.quiet, args.transient_slots)


#: The suite's tables: the file each is written to in --out, and the block of --docs DIR/LEADERBOARD.md.
SUITE_TABLES = {"board": "suite-board", "structure": "suite-structure", "tasks": "suite-tasks",
                "references": "suite-references"}


def _suite(args: argparse.Namespace) -> int:
    episodes, out = args.episodes or TEST_EPISODES, Path(args.out)
    tasks = args.tasks or list(SUITE)
    policies = list(args.policies or suite_policies()) + included(args.include)
    pages = {"LEADERBOARD.md": list(SUITE_TABLES.values())}
    if set(fleet_agents()) & set(policies):
        pages["LEARNED.md"] = ["fleet-generalization"]
    for page, names in pages.items() if args.docs else ():  # a missing block fails before any episode
        path = Path(args.docs) / page
        missing = [n for n in names if n not in block_names(path.read_text() if path.exists() else "")]
        if missing:
            raise ValueError(f"--docs {args.docs}: {path} has no generated block {', '.join(missing)}")
    rows, skipped, seconds = run_suite(policies, tasks, episodes, out, _play(args))
    board, refs = suite_table(rows, policies, tasks, skipped)
    reasons = skipped_summary(skipped)
    board += (f"\n\n{len(policies)} policies x {len(tasks)} tasks ({', '.join(tasks)}), test seeds 0-{episodes - 1}, "
              f"{seconds / 60:.1f} min with {args.workers} workers. n/a: the policy cannot act on the task"
              + (": " + "; ".join(reasons) + "." if reasons else ".")
              + " –: no score (the references do not separate on that task's seeds).")
    tables = {"board": board, "references": refs, "structure": structure_table(rows, tasks),
              "tasks": task_tables(rows, policies, tasks, skipped)}
    print(f"lawn benchmark --suite: {len(policies)} policies x {len(tasks)} tasks, {episodes} seeds each, "
          f"{seconds / 60:.1f} min; normalized score v{SCORE_VERSION} [95 %] (0 = {SCORE_LOW}, 100 = {SCORE_HIGH})")
    print(board)
    print(tables["structure"])
    for name, text in tables.items():
        (out / f"{name}.md").write_text(text + "\n")
    plot_profiles(read_csv(out / "per_slot.csv"), out / "per_slot.png", tasks, args.transient_slots)
    print(f"wrote {out}/episodes.csv, per_slot.csv, board.md (the scores), references.md (the references' costs), "
          "structure.md (cost structure, noise floor, headroom), tasks.md (every row per task) and per_slot.png")
    fleet = _fleet_sizes(args, policies, out)
    if args.docs:
        source = "lawn benchmark --suite --docs " + args.docs
        for name, text in tables.items():
            replace_block(Path(args.docs) / "LEADERBOARD.md", SUITE_TABLES[name], text, source=source)
        (Path(args.docs) / "figures").mkdir(parents=True, exist_ok=True)
        shutil.copy2(out / "per_slot.png", Path(args.docs) / "figures" / "suite-per-slot.png")
        if fleet:
            replace_block(Path(args.docs) / "LEARNED.md", "fleet-generalization", fleet, source=source)
        print(f"wrote the suite's blocks of {args.docs}/LEADERBOARD.md" + (" and LEARNED.md" if fleet else ""))
    return 0


def _fleet_sizes(args: argparse.Namespace, policies: list[str], out: Path) -> str:
    """The fleet networks among ``policies`` on every fleet size of the fleet-size table
    (:func:`training.benchmark.run_generalization`; ``--episodes`` caps its seeds per size); writes
    ``fleet_sizes.csv`` and ``.md``, returns the block (empty without fleet networks)."""
    import time



    agents = [p for p in fleet_agents() if p in policies]
    if not agents:
        return ""
    start = time.perf_counter()
    sizes = {k: min(n, args.episodes) if args.episodes else n for k, n in FLEET_SIZES.items()}
    rows = run_generalization(agents, sizes, _play(args))
    seeds = ", ".join(f"K = {k}: {n}" for k, n in sizes.items())
    # the targets are for the networks trained on mixed fleets, not the multi-agent ones trained at one K
    targeted = {a for a in agents if zoo_agents()[a.partition(":")[2]].get("trainer") == "fleet"}
    block = (f"Test seeds S..S+n-1 of each range S = {', '.join(map(str, TEST_RANGES))}, n per fleet size ({seeds}); "
             f"{args.workers} worker processes, {(time.perf_counter() - start) / 60:.1f} min.\n\n"
             + fleet_table(rows, agents, sizes, targeted))
    write_rows(rows, out / "fleet_sizes.csv")
    (out / "fleet_sizes.md").write_text(block + "\n")
    print(block)
    print(f"wrote {out}/fleet_sizes.csv and fleet_sizes.md (the fleet networks on K = 3 ... 64)")
    return block


def _learned(args: argparse.Namespace) -> int:
    episodes, out = args.episodes or TEST_EPISODES, Path(args.out)
    table = run_learned_protocol(list(args.policies or []) + included(args.include), out, episodes, _play(args))
    print(f"lawn benchmark --protocol learned: test seeds 0-{episodes - 1}, full unmodified episodes")
    print(table)
    print(f"wrote {out}/episodes.csv and {out}/summary.md")
    return 0
