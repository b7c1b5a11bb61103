"""``lawn gap``: the per-slot optimality gap of planners against the global reference, and the AO's
convergence at chosen slots (the analysis is :mod:`paper.experiments.gap`'s)."""

from __future__ import annotations

import argparse
from pathlib import Path

from agents import make_policy, policy_names
from evaluation.episode import Play
from paper.experiments.gap import (
    CONVERGENCE_SLOTS,
    convergence,
    format_convergence,
    format_gap_table,
    global_power_shares,
    run_gap,
    summarize_gaps,
    write_gap_outputs,
)

from .common import command, config_of, count, parse_overrides, policy_help, policy_name


def add(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> argparse.ArgumentParser:
    gp = command(sub, "gap", "workers", "quiet", "seed", "config", "overwrite")

    gp.add_argument("--policies", nargs="+", default=["ao-mpc", "rg-mpc"], type=policy_name, metavar="POLICY",
                    help=f"planners to compare: {', '.join(policy_names())} (default: ao-mpc rg-mpc)")
    gp.add_argument("--driver", default="ao-mpc", type=policy_name, metavar="POLICY",
                    help=policy_help("policy that runs the episodes (default: ao-mpc): ") + " too")
    gp.add_argument("--episodes", type=count, default=5,
                    help="episodes of the driver, seeds --seed.. (default: %(default)s)")
    gp.add_argument("--every", type=count, default=3, help="compare at every n-th slot (default: %(default)s)")
    gp.add_argument("--convergence-slots", type=int, nargs="*", default=list(CONVERGENCE_SLOTS),
                    help="slots of the first episode for the AO convergence figure "
                         "(none to skip; default: %(default)s)")
    gp.add_argument("--global-arg", action="append", default=[], metavar="KEY=VALUE",
                    help="resolution of the global reference, e.g. --global-arg drone_spacing_m=0.25")
    gp.add_argument("--out", default=None, help="output directory (default: runs/gap, or runs/gap-2, ... when an "
                                                "earlier run's results are there)")
    gp.set_defaults(default_out=lambda args: Path("runs/gap"))
    return gp


def run(args: argparse.Namespace) -> int:
    cfg = config_of(args)
    bad = [s for s in args.convergence_slots if not 0 <= s < cfg.num_slots]
    if bad:
        raise ValueError(f"--convergence-slots {bad}: slots must lie in [0, {cfg.num_slots - 1}] (the episode's slots)")
    global_settings = parse_overrides(args.global_arg, "--global-arg")
    make_policy(args.driver, cfg)  # fail fast
    for name in args.policies:
        if not callable(getattr(make_policy(name, cfg), "plan", None)):
            raise ValueError(f"--policies {name}: the gap compares planners' per-slot plans, and {name} does not "
                             "plan (the experts, the baselines and global-mpc do; a learned agent can drive: --driver)")
    make_policy("global-mpc", cfg, **global_settings)
    seeds = range(args.seed, args.seed + args.episodes)
    play = Play(args.workers, not args.quiet)
    rows = run_gap(args.policies, args.driver, cfg, seeds, args.every, play, global_settings)
    summary = summarize_gaps(rows)
    conv = convergence(cfg, args.convergence_slots, seed=args.seed, driver=args.driver,
                       global_settings=global_settings) if args.convergence_slots else []
    write_gap_outputs(rows, summary, conv, Path(args.out))
    print(f"lawn gap: driver {args.driver}, {args.episodes} episodes from seed {args.seed}, every {args.every} slots, "
          f"preset {args.preset}, K={cfg.num_agvs}; gap = (J^ - J^_global) / J^_global")
    print(format_gap_table(summary))
    print(f"the global reference gives some link less than 5 % of P_max on {global_power_shares(rows)} of "
          f"{len({(r.seed, r.slot) for r in rows})} slots")
    if conv:
        print(format_convergence(conv, args.convergence_slots))
    print(f"wrote {args.out}/gap_rows.csv, gap_summary.csv, gap_summary.md, gap.png"
          + (", convergence.csv, convergence.png" if conv else ""))
    return 0
