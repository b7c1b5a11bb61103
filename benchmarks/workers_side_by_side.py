"""``lawn benchmark`` with several worker counts, this tree beside another (the commit before a
change, checked out with ``git worktree add ../before <commit>``), interleaved: per worker count the
wall time of the whole command in each tree and their ratio.

    python benchmarks/workers_side_by_side.py --before ../before [--workers 1 2 8 16] [--episodes 16]
        [--repeats 2] [--markdown FILE]

The command is the paper protocol's six policies on the default task (``--policies rg-mpc ao-mpc
epa sf pid lqr --episodes N``), run as ``python -m training.cli`` with each tree first on
``PYTHONPATH``; numba's kernels are compiled into each tree's cache before the first timed run.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent
POLICIES = ["rg-mpc", "ao-mpc", "epa", "sf", "pid", "lqr"]


def _run(tree: Path, workers: int, episodes: int, out: str) -> float:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(tree), os.environ.get("PYTHONPATH", "")]))
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "training.cli", "benchmark", "--policies", *POLICIES, "--episodes",
                    str(episodes), "--workers", str(workers), "--quiet", "--out", out], cwd=tree, env=env, check=True,
                   capture_output=True)
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", required=True, help="the other tree (e.g. a git worktree of the commit before)")
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--episodes", type=int, default=16, help="seeds per policy (default: 16)")
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--markdown", default=None)
    args = parser.parse_args()
    trees = {"this tree": HERE, "before": Path(args.before).resolve()}
    with tempfile.TemporaryDirectory() as tmp:
        for tree in trees.values():  # compile and cache the kernels of each tree, untimed
            _run(tree, 1, 1, tmp)
        times = {(name, w): [] for name in trees for w in args.workers}
        for _ in range(args.repeats):
            for w in args.workers:
                for name, tree in trees.items():  # interleaved
                    times[(name, w)].append(_run(tree, w, args.episodes, tmp))
    lines = [f"`lawn benchmark --policies {' '.join(POLICIES)} --episodes {args.episodes} --workers W` "
             f"({len(POLICIES) * args.episodes} episodes), {os.cpu_count()} cores, median of {args.repeats} interleaved "
             "runs:", "", "| workers | this tree (s) | before (s) | before / this tree | this tree: speed-up over 1 "
             "worker | before: speed-up over 1 worker |", "|---|---|---|---|---|---|"]
    med = {k: statistics.median(v) for k, v in times.items()}
    one = args.workers[0]
    for w in args.workers:
        mine, theirs = med[("this tree", w)], med[("before", w)]
        lines.append(f"| {w} | {mine:.1f} | {theirs:.1f} | {theirs / mine:.2f} | "
                     f"{med[('this tree', one)] / mine:.2f}x | {med[('before', one)] / theirs:.2f}x |")
    text = "\n".join(lines)
    print(text)
    if args.markdown:
        Path(args.markdown).write_text(text + "\n")


if __name__ == "__main__":
    main()
