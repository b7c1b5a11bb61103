"""How many validation seeds a paired validation needs to see a change of 2 %, per suite task.

Model selection pairs each validation with the run's start on the same seeds (the common random
numbers of the paired reward: ``training.validation.validation_row``'s ``vs_start``, a mean of per-seed
relative differences with its 95 % t-interval). Even a policy that changes nothing that matters moves
every episode a little on poor links, where one flipped delivery sends an episode elsewhere, so the
interval has a floor: this script measures it with ``noise:dv-mpc`` (``dv-mpc`` on a 1.4 m drone grid
instead of 1.5 m: an immaterial change, the benchmark's noise floor) against ``dv-mpc`` on the
validation seeds 500000 + i, and gives the seeds an interval of ±2 % takes (the t-interval's
half-width at N seeds for the measured spread, at least 2 seeds). A learner one scale step from
its start moves its episodes at least this much.

    python benchmarks/validation_power.py [--episodes 100] [--tasks k16 k32] [--workers 2] [--markdown FILE]

Check: the pairing's premise, ``dv-mpc`` played twice on the same seeds gives the same costs.
Targets: ±2 % within the 100 validation episodes a run can afford (``--eval-episodes``).
"""

from __future__ import annotations

import argparse
import math

from report import finish  # benchmarks/report.py, beside this script
from scipy import stats

from evaluation.api import compare
from evaluation.seeds import VALIDATION_SEED_BASE
from evaluation.stats import paired_difference
from lawn_env.presets import SUITE

BOUND = 0.02  # the change a validation should see: its 95 % half-width
AFFORDABLE = 100  # validation episodes a run can afford every --eval-every steps


def seeds_for(half: float, n: int, bound: float = BOUND) -> int:
    """The fewest seeds (at least 2) whose 95 % t-interval half-width is at most ``bound``, for the
    spread that gave ``half`` on ``n`` seeds (:func:`evaluation.stats.mean_ci`'s interval)."""
    sd = half * math.sqrt(n) / stats.t.ppf(0.975, n - 1)
    size = max(2, math.ceil((1.959964 * sd / bound) ** 2))  # the normal quantile: a lower bound
    while stats.t.ppf(0.975, size - 1) * sd / math.sqrt(size) > bound:
        size += 1
    return size


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=100, help="validation seeds per task (default: 100)")
    parser.add_argument("--tasks", nargs="+", default=list(SUITE), choices=SUITE, metavar="TASK",
                        help=f"suite tasks (default: all: {' '.join(SUITE)})")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--markdown", default=None, help="write the table and marks here (a docs block)")
    args = parser.parse_args(argv)
    if args.episodes < 4:
        parser.error(f"--episodes {args.episodes}: at least 4 seeds for an interval")
    seeds = range(VALIDATION_SEED_BASE, VALIDATION_SEED_BASE + args.episodes)
    rows, targets = [], []
    for task in args.tasks:
        result = compare(["dv-mpc", "noise:dv-mpc"], config=task, seeds=seeds, workers=args.workers)
        mean, half, n = paired_difference(result.costs("noise:dv-mpc"), result.costs("dv-mpc"))
        needed = seeds_for(half, n)
        rows.append(f"| {task} | {n} | {100 * mean:+.2f} % ± {100 * half:.2f} % | {needed:,} |")
        targets.append((f"{task}: ±{100 * BOUND:g} % within {AFFORDABLE} validation seeds (needs {needed:,})",
                        needed <= AFFORDABLE))
    twice = [compare(["dv-mpc"], config=args.tasks[0], seeds=range(VALIDATION_SEED_BASE, VALIDATION_SEED_BASE + 2))
             for _ in range(2)]
    checks = [("dv-mpc played twice on the same seeds gives the same costs (the pairing's premise)",
               twice[0].costs("dv-mpc") == twice[1].costs("dv-mpc"))]
    lines = [(f"The paired change of `noise:dv-mpc` against `dv-mpc` on the validation seeds {seeds.start}.."
              f"{seeds.stop - 1} (mean of per-seed relative differences, 95 % t-interval: what model selection "
              f"reads), and the seeds an interval of ±{100 * BOUND:g} % takes."), "",
             "| task | seeds | noise:dv-mpc vs dv-mpc (paired) | seeds for ±2 % |", "|---|---|---|---|", *rows]
    print("\n".join(lines))
    return finish(checks, args.markdown, lines, targets)


if __name__ == "__main__":
    raise SystemExit(main())
