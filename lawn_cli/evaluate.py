"""``lawn evaluate``: any registered policy on seeded episodes, one row per episode (CSV/JSON),
with its normalized score."""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import lawn_env
from evaluation.episode import EpisodeSpec, write_results
from evaluation.report import format_table
from evaluation.rows import reduce
from evaluation.run import build_policy, evaluate
from evaluation.stats import SCORE_HIGH, SCORE_LOW

from .common import command, comparison_env, config_of, count, parse_overrides, policy_help, policy_name


def add(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> argparse.ArgumentParser:
    ev = command(sub, "evaluate", "workers", "quiet", "seed", "config", "split", "policy_arg", "overwrite")
    ev.add_argument("--policy", required=True, type=policy_name, help=policy_help())
    ev.add_argument("--env", default=None, type=comparison_env, metavar="ENV",
                    help=f"{', '.join(lawn_env.ENV_IDS)}: full episodes of the unmodified scenario (an agent trained "
                         "on an RL id plays its benchmark id through its own interface; default: lawn/Joint-v1, or "
                         "a trained agent's)")
    ev.add_argument("--episodes", type=count, default=10, help="episodes, seeds --seed.. (default: %(default)s)")
    ev.add_argument("--out", default=None,
                    help="rows file, .csv or .json (default: runs/evaluate/POLICY.csv, the policy's name with ':' and "
                         "'/' as '_', or POLICY-2.csv, ... when an earlier run's rows are there)")
    ev.add_argument("--no-score", action="store_true",
                    help="skip the normalized score (which runs its references, epa and dv-mpc, on the same seeds)")
    ev.set_defaults(default_out=default_out)  # resolved before the output is checked (lawn_cli.main)
    return ev


def default_out(args: argparse.Namespace) -> Path:
    """Where ``lawn evaluate`` writes without ``--out``: ``runs/evaluate/POLICY.csv``."""
    return Path("runs") / "evaluate" / (str(args.policy).replace(":", "_").replace("/", "_") + ".csv")


def run(args: argparse.Namespace) -> int:
    cfg = config_of(args)
    out = Path(args.out)  # resolved and claimed by lawn_cli before any work (never an earlier run's rows)
    if out.suffix.lower() not in (".csv", ".json"):
        raise ValueError(f"--out {args.out!r}: the extension must be .csv or .json")
    kwargs = parse_overrides(args.policy_arg, "--policy-arg")
    policy, _ = build_policy(args.policy, cfg, args.env, kwargs)  # fail fast on bad names and settings
    args.env = args.env or policy.env_id
    seeds = [args.seed + i for i in range(args.episodes)]
    # a reference run with --policy-arg is another policy under the reference's name: no score for it
    scored = not args.no_score and not (kwargs and args.policy in (SCORE_HIGH, SCORE_LOW))
    references = [p for p in (SCORE_HIGH, SCORE_LOW) if p != args.policy] if scored else []
    specs = [EpisodeSpec(name, args.env, cfg, s, kwargs if name == args.policy else {})
             for name in [args.policy, *references] for s in seeds]
    rows = evaluate(specs, workers=args.workers, progress=not args.quiet, desc=args.policy,
                    transient_slots=args.transient_slots)
    mine = [r for r in rows if r.policy == args.policy]
    write_results(mine, out)
    stats = reduce(rows)
    note = f" (score: {SCORE_LOW} and {SCORE_HIGH} on the same seeds)" if scored else \
        "" if args.no_score else f" (no score: --policy-arg changes the reference {args.policy} itself)"
    print(f"lawn evaluate: {args.policy} on {args.env}, {args.episodes} episodes from seed {args.seed}{note}")
    summary = stats.summary(args.env, [args.policy], reference=SCORE_HIGH if scored else None)
    print(format_table([replace(row, paired=None, score=row.score if scored else None) for row in summary]))
    print(f"wrote {len(mine)} {'row' if len(mine) == 1 else 'rows'} to {out}")
    return 0
