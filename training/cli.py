"""The ``lawn`` command line.

Subcommands read their choices from the package registries (env ids, presets).
``lawn demo``: one seeded episode of ``lawn/Joint-v0`` under a scripted policy.
``lawn evaluate``: any registered policy on seeded episodes, one row per episode (CSV/JSON).
``lawn benchmark``: the expert and the baselines on the same seeds, a table and a bar plot;
``--protocol learned`` the learned agents beside their anchors on 100 test seeds, ``--suite`` the
task suite's leaderboard (normalized scores, training/score.py).
``lawn dataset create``: a policy's episodes as a Minari dataset.
``lawn gap``: per-slot optimality gap of planners against the global reference, and the AO's
convergence at chosen slots.
``lawn train``: Stable-Baselines3 agents, behaviour cloning and multi-agent training (rl extra).
``lawn sweep``: a grid of config fields x policies x seeds into a tidy, resumable table.
``lawn figures``: the paper's experiments from tables (running missing sweeps).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import lawn_env
from agents.errors import MissingExtra
from agents.runs import read_run
from lawn_env import presets


def _parse_overrides(items: list[str], flag: str = "--set") -> dict:
    """``key=value`` pairs with dotted keys; values parsed as JSON when possible."""
    out = {}
    for item in items:
        key, _, raw = item.partition("=")
        if not _ or not key.strip():
            raise ValueError(f"{flag} expects KEY=VALUE (e.g. channel.blocklength=256), got {item!r}")
        try:
            out[key] = json.loads(raw)
        except json.JSONDecodeError:
            out[key] = raw
    return out


def _config(args) -> lawn_env.ScenarioConfig:
    cfg = presets.get(args.preset)
    return cfg.override(_parse_overrides(args.set)) if args.set else cfg


def _add_config_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--preset", default="default", choices=presets.names(), help="scenario preset (default: %(default)s)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="config override with a dotted key, e.g. --set channel.blocklength=256 (repeatable)")


def cmd_demo(args: argparse.Namespace) -> int:
    from .demo import run_demo

    cfg = _config(args)
    metrics = run_demo(args.seed, Path(args.out), config=cfg)
    print(f"lawn demo: lawn/Joint-v0, scripted heuristic, seed {args.seed}, K={cfg.num_agvs}, "
          f"R_th={cfg.channel.rate_threshold_bps_hz} bit/s/Hz, P_max={cfg.power_budget_dbw} dBW")
    for key in ("control_cost", "tracking_cost", "effort_cost", "rmse_m", "outage_rate", "outage_rate_predicted",
                "drone_path_length_m", "decision_time_median_s"):
        print(f"  {key:<24}{metrics[key]:.6g}")
    print(f"  {'rmse_per_agv_m':<24}{', '.join(f'{v:.3g}' for v in metrics['rmse_per_agv_m'])}")
    print(f"wrote {args.out}/metrics.json and {args.out}/paths.png")
    return 0


def _policy_kwargs(items: list[str]) -> dict:
    return _parse_overrides(items, "--policy-arg")


def cmd_evaluate(args: argparse.Namespace) -> int:
    from .evaluate import evaluate, format_table, summarize, write_rows

    cfg = _config(args)
    out = Path(args.out)
    if out.suffix.lower() not in (".csv", ".json"):
        raise ValueError(f"--out {args.out!r}: the extension must be .csv or .json")
    kwargs = _policy_kwargs(args.policy_arg)
    from agents import make_policy

    policy = make_policy(args.policy, cfg, env_id=args.env, **kwargs)  # fail fast on bad names and settings
    args.env = args.env or policy.env_id
    from .score import SCORE_HIGH, SCORE_LOW, scores_by_policy

    seeds = [args.seed + i for i in range(args.episodes)]
    # a reference run with --policy-arg is another policy under the reference's name: no score for it
    scored = not args.no_score and not (kwargs and args.policy in (SCORE_HIGH, SCORE_LOW))
    references = [p for p in (SCORE_HIGH, SCORE_LOW) if p != args.policy] if scored else []
    tasks = [(name, args.env, cfg, s, kwargs if name == args.policy else {}) for name in [args.policy, *references]
             for s in seeds]
    rows = evaluate(tasks, workers=args.workers, progress=not args.quiet, desc=args.policy)
    mine = [r for r in rows if r["policy"] == args.policy]
    write_rows(mine, out)
    scores = None if not scored else {
        p: score for (_, _, p), score in scores_by_policy(rows).items() if p == args.policy}
    note = f" (score: {SCORE_LOW} and {SCORE_HIGH} on the same seeds)" if scored else \
        "" if args.no_score else f" (no score: --policy-arg changes the reference {args.policy} itself)"
    print(f"lawn evaluate: {args.policy} on {args.env}, {args.episodes} episodes from seed {args.seed}{note}")
    print(format_table(summarize(mine), scores=scores))
    print(f"wrote {len(mine)} rows to {out}")
    return 0


def cmd_benchmark(args: argparse.Namespace) -> int:
    from agents import BENCHMARK_POLICIES, make_policy

    from .benchmark import run_benchmark

    if args.suite or args.protocol == "learned":
        return _benchmark_protocol(args)
    if args.tasks or args.docs:
        raise ValueError("--tasks and --docs belong to --suite (the task suite's leaderboard)")
    args.env = args.env or "lawn/Joint-v0"
    args.seed = 0 if args.seed is None else args.seed
    cfg = _config(args)
    args.policies = list(args.policies or BENCHMARK_POLICIES) + _included(args.include)
    for name in args.policies:
        make_policy(name, cfg, env_id=args.env)  # fail fast
    args.episodes = args.episodes or 20
    _, summary = run_benchmark(args.policies, args.env, cfg, args.episodes, args.seed, Path(args.out),
                               workers=args.workers, progress=not args.quiet)
    print(f"lawn benchmark: {args.env}, preset {args.preset}, K={cfg.num_agvs}, {args.episodes} seeds from "
          f"{args.seed}; mean ± 95 % interval")
    print((Path(args.out) / "summary.md").read_text().rstrip())
    print(f"wrote {args.out}/episodes.csv, summary.csv, summary.md, benchmark.png")
    return 0


def _benchmark_protocol(args: argparse.Namespace) -> int:
    """``lawn benchmark --protocol learned`` and ``lawn benchmark --suite``."""
    from .leaderboard import (
        run_learned_protocol,
        run_suite,
        skipped_summary,
        suite_policies,
        suite_table,
        write_leaderboard,
    )
    from .protocol import TEST_EPISODES

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
    episodes = args.episodes or TEST_EPISODES
    extra = _included(args.include)
    out = Path(args.out)
    if args.suite:
        from lawn_env.presets import SUITE

        tasks = args.tasks or list(SUITE)
        policies = list(args.policies or suite_policies()) + extra
        rows, skipped, seconds = run_suite(policies, tasks, episodes, out, workers=args.workers,
                                           progress=not args.quiet)
        board, refs = suite_table(rows, policies, tasks, skipped)
        print(f"lawn benchmark --suite: {len(policies)} policies x {len(tasks)} tasks, {episodes} seeds each, "
              f"{seconds / 60:.1f} min; normalized score v1 [95 %] (0 = epa, 100 = rg-mpc)")
        print(board)
        for line in skipped_summary(skipped):
            print(f"  n/a {line}")
        (out / "board.md").write_text(board + "\n")
        (out / "references.md").write_text(refs + "\n")
        print(f"wrote {out}/episodes.csv, board.md (the scores) and references.md (the references' costs)")
        if args.docs:
            print(f"wrote {write_leaderboard(Path(args.docs) / 'LEADERBOARD.md', board, refs, skipped, episodes, seconds, args.workers, tasks)}")
        return 0
    if args.tasks or args.docs:
        raise ValueError("--tasks and --docs belong to --suite (the task suite's leaderboard)")
    table = run_learned_protocol(list(args.policies or []) + extra, out, episodes, workers=args.workers,
                                 progress=not args.quiet)
    print(f"lawn benchmark --protocol learned: test seeds 0-{episodes - 1}, full unmodified episodes")
    print(table)
    print(f"wrote {out}/episodes.csv and {out}/summary.md")
    return 0


def cmd_gap(args: argparse.Namespace) -> int:
    from agents import make_policy

    from .gap import convergence, format_gap_table, global_power_shares, run_gap, summarize_gaps, write_gap_outputs

    cfg = _config(args)
    bad = [s for s in args.convergence_slots if not 0 <= s < cfg.num_slots]
    if bad:
        raise ValueError(f"--convergence-slots {bad}: slots must lie in [0, {cfg.num_slots - 1}] (the episode's slots)")
    global_settings = _parse_overrides(args.global_arg, "--global-arg")
    for name in args.policies + [args.driver]:
        make_policy(name, cfg)  # fail fast
    make_policy("global-mpc", cfg, **global_settings)
    rows = run_gap(args.policies, args.driver, cfg, args.episodes, args.seed, args.every, workers=args.workers,
                   progress=not args.quiet, global_settings=global_settings)
    summary = summarize_gaps(rows)
    conv = convergence(cfg, args.convergence_slots, seed=args.seed, driver=args.driver,
                       global_settings=global_settings) if args.convergence_slots else []
    write_gap_outputs(rows, summary, conv, Path(args.out))
    print(f"lawn gap: driver {args.driver}, {args.episodes} episodes from seed {args.seed}, every {args.every} slots, "
          f"preset {args.preset}, K={cfg.num_agvs}; gap = (J^ - J^_global) / J^_global")
    print(format_gap_table(summary))
    print(f"the global reference gives some link less than 5 % of P_max on {global_power_shares(rows)} of "
          f"{len({(r['seed'], r['slot']) for r in rows})} slots")
    if conv:
        print("convergence (paper's AO, 20 iterations, no early stop): J^ above the global reference")
        for slot in args.convergence_slots:
            sel = [r for r in conv if r["slot"] == slot]
            if sel:
                first = next(r for r in sel if r["block"] == "drone")
                print(f"  slot {slot}: after iteration 1 {first['objective'] / first['global_objective'] - 1:+.2%}, "
                      f"after 20 {sel[-1]['objective'] / sel[-1]['global_objective'] - 1:+.2%}, "
                      f"rg-mpc {sel[-1]['rg_mpc_objective'] / sel[-1]['global_objective'] - 1:+.3%}")
    print(f"wrote {args.out}/gap_rows.csv, gap_summary.csv, gap_summary.md, gap.png"
          + (", convergence.csv, convergence.png" if conv else ""))
    return 0


def cmd_train(args: argparse.Namespace) -> int:
    try:
        import stable_baselines3  # noqa: F401
        import supersuit  # noqa: F401
    except ImportError as exc:
        raise MissingExtra(f"training needs the rl extra ({exc.name} is missing): bash scripts/setup.sh full, "
                           "or pip install torch==2.13.0 && pip install -e '.[rl]'") from None
    from .train import resume, train, train_seeds

    if args.resume:
        summary = resume(Path(args.resume), timesteps=args.timesteps, progress=not args.quiet)
        out = args.resume
        start = summary["resumed_from"]
        print(f"lawn train: resumed {out} from its checkpoint at {start} steps" if start is not None else
              f"lawn train: {out} had no checkpoint; trained it again from the start")
    else:
        missing = [flag for flag, value in (("--algo", args.algo), ("--env", args.env), ("--out", args.out)) if not value]
        if missing:
            raise ValueError(f"lawn train needs {', '.join(missing)} (or --resume DIR)")
        if args.timesteps is None:
            raise ValueError("lawn train needs --timesteps")
        kwargs = dict(algo=args.algo, env_id=args.env, config=_config(args), timesteps=args.timesteps,
                      hp_overrides=_parse_overrides(args.hp, "--hp"), n_envs=args.n_envs, eval_every=args.eval_every,
                      eval_episodes=args.eval_episodes, checkpoint_every=args.checkpoint_every,
                      init_from=Path(args.init_from) if args.init_from else None, interface=args.interface,
                      vec=args.vec, dataset=args.dataset)
        if args.seeds:
            result = train_seeds(args.seeds, Path(args.out), workers=args.workers, progress=not args.quiet,
                                 backend=args.backend, **kwargs)
            print(f"lawn train: {args.algo} on {args.env}, seeds {args.seeds}")
            for run in result["runs"]:
                print(f"  seed {run['seed']}: best validation cost {run['best_validation_cost']:.6g} "
                      f"at {run['best_at_timesteps']} steps, {run['timesteps']} steps in {run['wall_time_s']:.0f} s")
            print(f"  across seeds: {result['best_validation_cost_mean']:.6g} ± "
                  f"{result['best_validation_cost_ci95']:.3g} (95 % interval)")
            print(f"wrote {args.out}/seed-*/ and {args.out}/seeds.json")
            return 0
        summary = train(seed=args.seed, out_dir=Path(args.out), progress=not args.quiet, **kwargs)
        out = args.out
    print(f"lawn train: {summary['algo']} on {summary['env']}, seed {summary['seed']}, "
          f"{summary['timesteps']} steps in {summary['wall_time_s']:.1f} s")
    for key in ("final_validation_cost", "best_validation_cost", "best_at_timesteps", "bc_loss_first", "bc_loss_last"):
        if summary.get(key) is not None:
            print(f"  {key:<24}{summary[key]:.6g}")
    print(f"wrote {out}/ (model.zip, run.json, config.json, hyperparams.json, learning curve, summary.md)")
    return 0


def cmd_zoo(args: argparse.Namespace) -> int:
    from .zoo import build_zoo, format_zoo_list, train_recipes

    if args.action == "list":
        print(format_zoo_list())
        return 0
    try:
        import stable_baselines3  # noqa: F401
    except ImportError:
        raise MissingExtra("lawn zoo train/build need the rl extra: bash scripts/setup.sh full") from None
    if args.action == "train":
        dirs = train_recipes(Path(args.runs), args.only, workers=args.workers, progress=not args.quiet)
        print(f"lawn zoo train: {len(dirs)} runs in {args.runs}")
        return 0
    table = build_zoo(Path(args.runs), Path(args.doc), Path(args.readme) if args.readme else None,
                      workers=args.workers, progress=not args.quiet)
    print(table)
    print(f"wrote {args.doc}" + (f", the table in {args.readme}" if args.readme else "") + f" and {ZOO_HINT}")
    return 0


def cmd_dataset(args: argparse.Namespace) -> int:
    from .datasets import create_dataset

    dataset = create_dataset(args.policy, args.env, args.episodes, args.seed, args.dataset_id, task=args.task,
                             progress=not args.quiet)
    steps = int(dataset.total_steps)
    print(f"lawn dataset create: {args.dataset_id}: {args.episodes} episodes (seeds {args.seed}-"
          f"{args.seed + args.episodes - 1}) of {args.policy} on {args.env}, task {args.task}, {steps} steps")
    run = "".join(c if c.isalnum() or c in "-_." else "-" for c in args.dataset_id.rsplit("/", 1)[-1])
    print(f"load it with minari.load_dataset({args.dataset_id!r}); clone it with lawn train --algo bc --env {args.env} "
          f"--preset {args.task} --dataset {args.dataset_id} --timesteps {steps} --out runs/bc-{run}"
          + ("" if args.policy == "rg-mpc" else f" --hp expert={args.policy} (DAgger relabels with the same policy)"))
    return 0


ZOO_HINT = "agents/zoo/<name>/ (policy.zip, normalizer.npz, agent.json)"


def cmd_sweep(args: argparse.Namespace) -> int:
    from .sweep import load_spec, run_sweep, summarize_sweep

    spec = load_spec(args.spec)
    rows = run_sweep(spec, Path(args.out), workers=args.workers, backend=args.backend, progress=not args.quiet,
                     extend=args.extend)
    print(f"lawn sweep {spec['name']}: {len(rows)} rows in {args.out}; mean ± 95 % interval")
    print(summarize_sweep(rows, list(spec["grid"])))
    return 0


def cmd_figures(args: argparse.Namespace) -> int:
    from .figures import make_figures

    if args.docs and args.quick:
        raise ValueError("--docs writes the published reproduction; it takes the full set, not --quick")
    start = time.perf_counter()
    timings = make_figures(args.names, Path(args.out), quick=args.quick, workers=args.workers, progress=not args.quiet)
    for name, seconds in timings.items():
        print(f"  {name:<12}{seconds:8.1f} s   {args.out}/{name}.png, .pdf, data/{name}.csv")
    print(f"lawn figures: {len(timings)} figures in {time.perf_counter() - start:.1f} s"
          + (" (--quick)" if args.quick else ""))
    from .figures import check_claims, format_claims, write_reproduction

    table = format_claims(check_claims(Path(args.out), args.names))
    (Path(args.out) / "claims.md").write_text(table + "\n")
    print(table)
    if args.docs:
        print(f"wrote {write_reproduction(Path(args.out), Path(args.docs))}")
    return 0


def _int_at_least(low: int):
    """argparse type: an integer >= ``low``, with the bound in the message."""

    def parse(value: str) -> int:
        try:
            number = int(value)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{value!r} is not an integer") from None
        if number < low:
            raise argparse.ArgumentTypeError(f"{number} must be >= {low}")
        return number

    parse.__name__ = f"integer >= {low}"
    return parse


_COUNT, _SEED = _int_at_least(1), _int_at_least(0)


def _policy_name(value: str) -> str:
    from agents.learned import learned_name_forms
    from agents.policies import is_policy_name, policy_names

    if not is_policy_name(value):
        raise argparse.ArgumentTypeError(
            f"unknown policy {value!r}; valid: {', '.join(policy_names())}, or {learned_name_forms()}")
    return value


def _included(paths: list[str]) -> list[str]:
    """Policy names for trained run directories: marl:, bc: or sb3: by what run.json says."""
    return [read_run(path, "--include").policy_name for path in paths]


def build_parser() -> argparse.ArgumentParser:
    from .gap import CONVERGENCE_SLOTS

    parser = argparse.ArgumentParser(prog="lawn", description="Wireless predictive control over low-altitude networks.")
    parser.add_argument("--version", action="version", version=f"lawn {lawn_env.__version__}")
    parser.add_argument("--debug", action="store_true", help="on an error, show the full traceback")
    debug = argparse.ArgumentParser(add_help=False)  # --debug also after the subcommand
    debug.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help="on an error, show the traceback")
    sub = parser.add_subparsers(dest="command", required=True)

    def command(name: str, **kwargs) -> argparse.ArgumentParser:
        return sub.add_parser(name, parents=[debug], **kwargs)

    demo = command("demo", help="one seeded episode of lawn/Joint-v0 under a scripted policy")
    demo.add_argument("--seed", type=_SEED, default=0)
    demo.add_argument("--out", default="runs/demo", help="output directory (default: %(default)s)")
    _add_config_args(demo)
    demo.set_defaults(func=cmd_demo)

    from agents import BENCHMARK_POLICIES, policy_names
    from agents.learned import learned_name_forms

    workers_default = min(2, os.cpu_count() or 1)
    ev = command("evaluate", help="run a policy on seeded episodes and write one row per episode")
    ev.add_argument("--policy", required=True, type=_policy_name,
                    help=f"{', '.join(policy_names())}, or {learned_name_forms(' / ')} for learned agents")
    ev.add_argument("--env", default=None, choices=list(lawn_env.ENV_IDS),
                    help="default: lawn/Joint-v0, or the env a trained agent was trained on")
    ev.add_argument("--episodes", type=_COUNT, default=10)
    ev.add_argument("--seed", type=_SEED, default=0, help="first seed; episode i uses seed + i")
    ev.add_argument("--out", required=True, help="rows file, .csv or .json")
    ev.add_argument("--policy-arg", action="append", default=[], metavar="KEY=VALUE",
                    help="policy setting, e.g. --policy-arg tolerance=1e-3 (repeatable)")
    ev.add_argument("--workers", type=_COUNT, default=workers_default, help="processes (default: %(default)s)")
    ev.add_argument("--no-score", action="store_true",
                    help="skip the normalized score (which runs epa and rg-mpc on the same seeds)")
    ev.add_argument("--quiet", action="store_true", help="no progress bar")
    _add_config_args(ev)
    ev.set_defaults(func=cmd_evaluate)

    bm = command("benchmark", help="the expert and the baselines on the same seeded episodes; --protocol learned "
                                   "and --suite: the learned agents' protocol and the task suite's leaderboard")
    bm.add_argument("--policies", nargs="+", default=None, type=_policy_name,
                    help=f"{', '.join(policy_names())}, or {learned_name_forms(' / ')} (default: "
                         f"{' '.join(BENCHMARK_POLICIES)}; with --protocol learned every shipped agent with its "
                         "anchor and the references; with --suite every expert, baseline, shipped agent and the "
                         "stake and distance anchors)")
    bm.add_argument("--protocol", choices=["paper", "learned"], default="paper",
                    help="paper (default): the policies on --episodes seeds of one scenario; learned: agents "
                         "beside rg-mpc, epa and their own anchors on the 100 test seeds, with the normalized score")
    bm.add_argument("--suite", action="store_true",
                    help="the task suite (lawn_env.presets.SUITE): normalized score of every policy on every task")
    bm.add_argument("--tasks", nargs="+", default=None, choices=presets.names(), metavar="TASK",
                    help="--suite: only these tasks (presets)")
    bm.add_argument("--docs", default=None, metavar="DIR", help="--suite: also write DIR/LEADERBOARD.md")
    bm.add_argument("--env", default=None, choices=list(lawn_env.ENV_IDS),
                    help="the env of every policy (default: lawn/Joint-v0; --protocol learned and --suite run each "
                         "policy on its own env)")
    bm.add_argument("--include", nargs="*", default=[], metavar="DIR",
                    help="trained run directories (lawn train) to add to the comparison")
    bm.add_argument("--episodes", type=_COUNT, default=None,
                    help="seeds from --seed (default: 20; 100 test seeds for --protocol learned and --suite)")
    bm.add_argument("--seed", type=_SEED, default=None,
                    help="first seed (default: 0; --protocol learned and --suite fix the test seeds 0..N-1)")
    bm.add_argument("--out", default="runs/benchmark", help="output directory (default: %(default)s)")
    bm.add_argument("--workers", type=_COUNT, default=workers_default, help="processes (default: %(default)s)")
    bm.add_argument("--quiet", action="store_true", help="no progress bar")
    _add_config_args(bm)
    bm.set_defaults(func=cmd_benchmark)

    from .train import ALGOS, TRAIN_ENV_IDS

    tr = command("train", help="train a Stable-Baselines3 agent (or behaviour cloning) on a lawn env")
    tr.add_argument("--algo", choices=ALGOS)
    tr.add_argument("--env", choices=TRAIN_ENV_IDS, help="lawn/Parallel-v0 is the multi-agent PettingZoo env")
    tr.add_argument("--timesteps", type=_COUNT, help="environment steps (for bc: expert transitions)")
    tr.add_argument("--seed", type=_SEED, default=0)
    tr.add_argument("--seeds", type=_SEED, nargs="+", metavar="SEED",
                    help="train one run per seed into OUT/seed-<s> (process pool, --workers) and summarize across seeds")
    tr.add_argument("--workers", type=_COUNT, default=workers_default, help="processes for --seeds (default: %(default)s)")
    tr.add_argument("--backend", choices=["process", "ray"], default="process",
                    help="where --seeds runs go: a process pool (default) or Ray, as lawn sweep")
    tr.add_argument("--interface", default=None, choices=["rl", "v0"],
                    help="the RL interface (default: the hyperparameter file's, rl) or the plain v0 interface")
    tr.add_argument("--out", help="run directory")
    tr.add_argument("--n-envs", type=_COUNT, default=None, help="parallel environments (default: the hyperparameter file)")
    tr.add_argument("--hp", action="append", default=[], metavar="KEY=VALUE",
                    help="hyperparameter override, e.g. --hp learning_rate=1e-4 (repeatable)")
    tr.add_argument("--eval-every", type=_COUNT, default=10000,
                    help="steps between validations (full unmodified episodes, realized control cost)")
    tr.add_argument("--eval-episodes", type=_COUNT, default=5, help="validation episodes (seeds 500000 + i)")
    tr.add_argument("--checkpoint-every", type=_COUNT, default=10000, help="steps between checkpoints")
    tr.add_argument("--init-from", metavar="DIR", help="start from a behaviour-cloned run of the same algorithm")
    tr.add_argument("--resume", metavar="DIR", help="continue an interrupted run from its last checkpoint")
    tr.add_argument("--vec", choices=["dummy", "native"], default="dummy",
                    help="SB3 DummyVecEnv of single envs (default) or lawn's batched vector env (Joint-v0, "
                         "Comm-v0 and their RL ids, any --interface)")
    tr.add_argument("--dataset", metavar="ID", help="bc: clone the episodes of this Minari dataset (lawn dataset create) "
                                                     "instead of live expert rollouts; --timesteps caps the transitions")
    tr.add_argument("--quiet", action="store_true")
    _add_config_args(tr)
    tr.set_defaults(func=cmd_train)

    zo = command("zoo", help="shipped learned agents: list them, train their recipes, benchmark and export")
    zo.add_argument("action", nargs="?", default="list", choices=["list", "train", "build"])
    zo.add_argument("--runs", default="runs/agents", help="training runs, one folder per recipe (default: %(default)s)")
    zo.add_argument("--only", nargs="+", metavar="NAME", help="train only these recipes")
    zo.add_argument("--doc", default="docs/LEARNED.md", help="build: the table's document (default: %(default)s)")
    zo.add_argument("--readme", default="README.md", help="build: README whose learned-agents block is replaced")
    zo.add_argument("--workers", type=_COUNT, default=workers_default)
    zo.add_argument("--quiet", action="store_true")
    zo.set_defaults(func=cmd_zoo)

    ds = command("dataset", help="record a policy's episodes as a Minari dataset (data extra)")
    ds.add_argument("action", choices=["create"])
    ds.add_argument("--policy", required=True, type=_policy_name,
                    help=f"any policy: {', '.join(policy_names())}, or {learned_name_forms(' / ')}")
    ds.add_argument("--env", required=True, choices=["lawn/Joint-v0", "lawn/Comm-v0"])
    ds.add_argument("--episodes", type=_COUNT, required=True)
    ds.add_argument("--seed", type=_SEED, default=0, help="first seed; episode i uses seed + i (as lawn evaluate)")
    ds.add_argument("--dataset-id", required=True, metavar="ID",
                    help="Minari id, e.g. lawn/comm/rg-mpc-v0; stored under MINARI_DATASETS_PATH")
    ds.add_argument("--task", default="default", choices=presets.names(), help="scenario preset (default: %(default)s)")
    ds.add_argument("--quiet", action="store_true")
    ds.set_defaults(func=cmd_dataset)

    sw = command("sweep", help="run a grid of config fields x policies x seeds into a tidy table")
    sw.add_argument("spec", help="sweep spec (YAML or JSON)")
    sw.add_argument("--out", required=True, help="table (CSV); finished rows are skipped on rerun")
    sw.add_argument("--workers", type=_COUNT, default=workers_default)
    sw.add_argument("--backend", choices=["process", "ray"], default="process",
                    help="process pool (default) or Ray (local, or the cluster at $RAY_ADDRESS)")
    sw.add_argument("--extend", action="store_true",
                    help="keep rows of the table that this spec would not produce (another spec or version)")
    sw.add_argument("--quiet", action="store_true")
    sw.set_defaults(func=cmd_sweep)

    from .figures import EXPERIMENTS

    fg = command("figures", help="the paper's experiments from tidy tables (running missing sweeps)")
    fg.add_argument("names", nargs="*", choices=[[]] + list(EXPERIMENTS), metavar="NAME",
                    help=f"figures to make (default: all): {', '.join(EXPERIMENTS)}")
    fg.add_argument("--out", default="runs/figures")
    fg.add_argument("--quick", action="store_true", help="reduced seeds, grids and episode length (tests)")
    fg.add_argument("--workers", type=_COUNT, default=workers_default)
    fg.add_argument("--docs", default=None, metavar="DIR",
                    help="also write DIR/REPRODUCTION.md and copy the figures to DIR/figures/reproduction/")
    fg.add_argument("--quiet", action="store_true")
    fg.set_defaults(func=cmd_figures)

    gp = command("gap", help="per-slot optimality gap of planners against the global reference")
    gp.add_argument("--policies", nargs="+", default=["ao-mpc", "rg-mpc"], choices=policy_names())
    gp.add_argument("--driver", default="ao-mpc", choices=policy_names(), help="policy that runs the episodes")
    gp.add_argument("--episodes", type=_COUNT, default=5)
    gp.add_argument("--seed", type=_SEED, default=0)
    gp.add_argument("--every", type=_COUNT, default=3, help="compare at every n-th slot (default: %(default)s)")
    gp.add_argument("--convergence-slots", type=int, nargs="*", default=list(CONVERGENCE_SLOTS),
                    help="slots of the first episode for the AO convergence figure (none to skip)")
    gp.add_argument("--global-arg", action="append", default=[], metavar="KEY=VALUE",
                    help="resolution of the global reference, e.g. --global-arg drone_spacing_m=0.25")
    gp.add_argument("--out", default="runs/gap")
    gp.add_argument("--workers", type=_COUNT, default=workers_default)
    gp.add_argument("--quiet", action="store_true")
    _add_config_args(gp)
    gp.set_defaults(func=cmd_gap)
    return parser


#: Commands whose --out is a file (its folder must be writable) or a folder, checked before any work.
_FILE_OUT = ("evaluate", "sweep")
_DIR_OUT = ("demo", "benchmark", "gap", "figures")


def _check_out(command: str, out) -> None:
    """``--out`` must be writable before hours are spent computing what goes there."""
    if out is None or command not in _FILE_OUT + _DIR_OUT:
        return
    path = Path(out)
    folder = path.parent if command in _FILE_OUT else path
    if command in _FILE_OUT and path.is_dir():
        raise ValueError(f"--out {str(path)!r} is a directory; give a file")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        probe = folder / f".lawn-write-test-{os.getpid()}"
        probe.write_text("")
        probe.unlink()
    except OSError as exc:
        raise ValueError(f"--out {str(path)!r}: cannot write to {str(folder)!r} ({exc.strerror or exc})") from None


def _one_line(exc: BaseException) -> str:
    """A config validation error as ``field: message (got value)``, several joined by ``; ``."""
    from pydantic import ValidationError

    if isinstance(exc, ValidationError):
        parts = []
        for err in exc.errors():
            field = ".".join(str(p) for p in err["loc"]) or exc.title
            parts.append(f"{field}: {err['msg']} (got {err['input']!r})" if "input" in err else f"{field}: {err['msg']}")
        return f"invalid {exc.title}: " + "; ".join(parts)
    return " ".join(str(exc).split("\n")) if str(exc) else type(exc).__name__


def main(argv: list[str] | None = None) -> int:
    """The ``lawn`` command. Errors print one line and exit non-zero (2: bad input, 3: a missing
    extra, 130: interrupted, 1: anything else, which is a bug); ``--debug`` shows the traceback."""
    args = build_parser().parse_args(argv)
    try:
        _check_out(args.command, getattr(args, "out", None))
        return args.func(args)
    except BaseException as exc:
        if args.debug or isinstance(exc, SystemExit):
            raise
        if isinstance(exc, KeyboardInterrupt):
            print(f"lawn {args.command}: interrupted", file=sys.stderr)
            return 130
        if isinstance(exc, MissingExtra):
            print(f"lawn {args.command}: error: {exc}", file=sys.stderr)
            return 3
        if isinstance(exc, (ValueError, TypeError, OSError)):  # bad values, names, files: one clear line
            print(f"lawn {args.command}: error: {_one_line(exc)}", file=sys.stderr)
            return 2
        if isinstance(exc, Exception):
            print(f"lawn {args.command}: internal error: {type(exc).__name__}: {exc} "
                  "(rerun with --debug for the traceback, and please report it)", file=sys.stderr)
            return 1
        raise


if __name__ == "__main__":
    sys.exit(main())
