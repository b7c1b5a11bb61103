"""``lawn demo``: one seeded episode of ``lawn/Joint-v1`` under a scripted policy."""

from __future__ import annotations

import argparse
from pathlib import Path

from evaluation.render import run_demo

from .common import command, config_of


def add(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> argparse.ArgumentParser:
    demo = command(sub, "demo", "one_seed", "config", "overwrite")
    demo.add_argument("--out", default=None, help="output directory (default: runs/demo, or runs/demo-2, ... when an "
                                                  "earlier run's results are there)")
    demo.set_defaults(default_out=lambda args: Path("runs/demo"))
    return demo


def run(args: argparse.Namespace) -> int:
    cfg = config_of(args)
    metrics = run_demo(args.seed, Path(args.out), config=cfg)
    print(f"lawn demo: lawn/Joint-v1, scripted heuristic, seed {args.seed}, K={cfg.num_agvs}, "
          f"R_th={cfg.channel.rate_threshold_bps_hz} bit/s/Hz, P_max={cfg.power_budget_dbw} dBW")
    for key in ("control_cost", "tracking_cost", "effort_cost", "rmse_m", "outage_rate", "outage_rate_predicted",
                "drone_path_length_m", "decision_time_median_s"):
        print(f"  {key:<24}{metrics[key]:.6g}")
    print(f"  {'rmse_per_agv_m':<24}{', '.join(f'{v:.3g}' for v in metrics['rmse_per_agv_m'])}")
    print(f"wrote {args.out}/metrics.json and {args.out}/paths.png")
    return 0
