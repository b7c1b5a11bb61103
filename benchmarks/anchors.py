"""How good the RL interface's zero action is: the anchors a learner starts from,
against ``rg-mpc`` on the same seeds, in one run.

Every row plays full 120-slot episodes of the unmodified ``lawn/Comm-v1`` scenario and reports the
realized control cost (mean and 95 % interval over seeds) and the paired per-seed difference
against ``rg-mpc``. The rows are the anchor policies of :mod:`agents.anchors` (``anchor:NAME``,
the rows the learned protocol puts beside every agent):

* ``hover`` -- the v0 interface's zero action (the drone hovers at its start, equal power);
* ``distance`` -- the anchored scheme with the distance prior (drone over the AGVs' centroid, the
  split that equalizes every link's outage), the RL interface before its stake prior;
* ``stake`` -- the anchored scheme with the stake prior (``lawn_env.interface``), the RL
  interface's default: the zero action a learner of ``lawn/CommRL-v1`` or ``lawn/JointRL-v1``
  starts from.

The seeds are the validation seeds (``training.validation.VALIDATION_SEED_BASE`` on): the anchor was
chosen on them, never on the benchmark's test seeds.

Usage: ``python benchmarks/anchors.py [--episodes 20] [--markdown FILE]``
"""

from __future__ import annotations

import argparse
from pathlib import Path

from agents import ANCHORS
from evaluation.episode import EpisodeSpec
from evaluation.run import evaluate
from evaluation.seeds import VALIDATION_SEED_BASE
from evaluation.stats import mean_ci, paired_difference
from lawn_env import ScenarioConfig

ENV_ID = "lawn/Comm-v1"


def episode_costs(anchor: str, seeds: list[int], workers: int) -> dict[int, float]:
    """Realized control cost of a policy (an ``anchor:NAME``, or the reference) per seed (full episodes of the
    unmodified scenario, :class:`agents.AnchorPolicy`)."""
    rows = evaluate([EpisodeSpec(anchor, ENV_ID, ScenarioConfig(), s, {}) for s in seeds], workers=workers,
                    progress=False)
    return {r.seed: r.control_cost for r in rows}


def _relative(x: float, sign: bool = True) -> str:
    """A relative difference as a percentage, or as a factor once it is past 10x."""
    if abs(x) >= 10:
        return f"{x:,.0f}x" if not sign else f"{1 + x:,.0f}x the cost"
    return f"{x:+.1%}" if sign else f"{x:.1%}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--episodes", type=int, default=20, help="validation seeds (default: 20)")
    parser.add_argument("--markdown", help="also write the table of this run to this file")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args(argv)
    seeds = [VALIDATION_SEED_BASE + i for i in range(args.episodes)]
    reference = episode_costs("rg-mpc", seeds, args.workers)
    rows = [("rg-mpc (reference)", reference)] + [(f"anchor:{name}", episode_costs(f"anchor:{name}", seeds, args.workers))
                                                  for name in ANCHORS]
    lines = [f"Zero action of each anchor on {ENV_ID}, {len(seeds)} validation seeds "
             f"({seeds[0]}-{seeds[-1]}), full unmodified episodes:", "",
             "| policy | control cost | vs rg-mpc (paired) | worst seed vs rg-mpc |", "|---|---|---|---|"]
    for name, costs in rows:
        mean, half = mean_ci(costs.values())
        if costs is reference:
            lines.append(f"| {name} | {mean:,.0f} ± {half:,.0f} | – | – |")
            continue
        diff, dhalf, _ = paired_difference(costs, reference)
        worst = max(costs[s] / reference[s] - 1 for s in seeds)
        lines.append(f"| {name} | {mean:,.0f} ± {half:,.0f} | {_relative(diff)} ± {_relative(dhalf, sign=False)} "
                     f"| {_relative(worst)} |")
    text = "\n".join(lines)
    print(text)
    if args.markdown:
        Path(args.markdown).write_text(text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
