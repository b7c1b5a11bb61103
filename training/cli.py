"""The ``lawn`` command line.

Subcommands read their choices from the package registries (env ids, presets).
``lawn demo``: one seeded episode of ``lawn/Joint-v0`` under a scripted policy.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import lawn_env
from lawn_env import presets


def _parse_overrides(items: list[str]) -> dict:
    """``key=value`` pairs with dotted keys; values parsed as JSON when possible."""
    out = {}
    for item in items:
        if "=" not in item:
            raise SystemExit(f"--set expects key=value (e.g. channel.blocklength=256), got {item!r}")
        key, raw = item.split("=", 1)
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


def cmd_demo(args) -> int:
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


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="lawn", description="Wireless predictive control over low-altitude networks.")
    parser.add_argument("--version", action="version", version=f"lawn {lawn_env.__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="one seeded episode of lawn/Joint-v0 under a scripted policy")
    demo.add_argument("--seed", type=int, default=0)
    demo.add_argument("--out", default="runs/demo", help="output directory (default: %(default)s)")
    _add_config_args(demo)
    demo.set_defaults(func=cmd_demo)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except ValueError as exc:  # bad config values or names: one clear line, no traceback
        print(f"lawn {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
