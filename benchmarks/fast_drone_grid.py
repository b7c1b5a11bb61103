"""The drone grid of the ``limit:fast-drone`` row (evaluation/run.py): ``rg-mpc`` at the config's
largest speed (300 m/s, a 150 m reach) with its drone grid capped at several point counts, against
``rg-mpc`` at 15 m/s on the same seeds. Prints, per task and cap, the wall time of the episodes and
the row's headroom (geometric mean of the per-seed cost ratios - 1, 95 % bootstrap interval); the
reference is the planner's default cap (10,000 points), in the same run.

    python benchmarks/fast_drone_grid.py [--episodes 20] [--tasks default wide-k8] [--workers 2]
"""

from __future__ import annotations

import argparse
import time

from evaluation.cells import fmt_geometric
from evaluation.episode import EpisodeSpec
from evaluation.run import LIMIT_SETTINGS, evaluate
from evaluation.stats import paired_geometric
from lawn_env import presets

DEFAULT_CAP = 10_000  # agents.rg_mpc.ReducedSettings.max_drone_points


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--tasks", nargs="+", default=["default", "wide-k8"], choices=presets.names())
    parser.add_argument("--caps", nargs="+", type=int, default=[DEFAULT_CAP, 2_000, 1_000, 500])
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    chosen = LIMIT_SETTINGS["limit:fast-drone"]["max_drone_points"]
    print(f"| task | drone grid cap | wall time ({args.episodes} episodes, {args.workers} workers) | time vs cap "
          f"{DEFAULT_CAP:,} | fast drone vs rg-mpc (geometric, seeds won) |")
    print("|---|---|---|---|---|")
    for task in args.tasks:
        config = presets.get(task)
        fast = config.override({"drone.max_speed_mps": 300.0})
        seeds = range(args.episodes)
        base = evaluate([EpisodeSpec("rg-mpc", "lawn/Joint-v1", config, s, {}) for s in seeds], workers=args.workers,
                        progress=False)
        reference = {r.seed: r.control_cost for r in base}
        times = {}
        for cap in args.caps:
            start = time.perf_counter()
            rows = evaluate([EpisodeSpec("rg-mpc", "lawn/Joint-v1", fast, s, {"max_drone_points": cap}) for s in seeds],
                            workers=args.workers, progress=False)
            times[cap] = time.perf_counter() - start
            g = paired_geometric({r.seed: r.control_cost for r in rows}, reference)
            ratio = times[cap] / times[args.caps[0]]
            mark = " (limit:fast-drone)" if cap == chosen else ""
            print(f"| {task} | {cap:,}{mark} | {times[cap]:.1f} s | {ratio:.2f} | {fmt_geometric(g)} |", flush=True)


if __name__ == "__main__":
    main()
