"""A benchmark of this tree beside another checkout (the commit before a change), interleaved.

    git worktree add ../before <commit>
    python benchmarks/side_by_side.py --before ../before [--script benchmarks/hot_paths.py] [--pairs 5]
        [-- ARGS for the script]

The script (any benchmark here that takes ``--json FILE`` and writes a flat {figure: value} object)
runs alternately in the other checkout and in this one, each with its own tree first on
``PYTHONPATH`` and one untimed run first (numba's kernels compiled into each tree's cache). Prints,
per figure, both medians and the median of the per-pair ratios (this tree / before) with their
range: a ratio below 1 is faster here. Ratios of interleaved pairs, not times: the machine's speed
drifts between runs.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent


def _run(tree: Path, script: str, extra: list[str]) -> dict[str, float]:
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "figures.json"
        env = {**os.environ, "PYTHONPATH": str(tree)}
        subprocess.run([sys.executable, str(tree / script), "--json", str(out), *extra], cwd=tree, env=env,
                       check=True, stdout=subprocess.DEVNULL)
        return json.loads(out.read_text())


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--before", required=True, type=Path, help="the other checkout (git worktree add)")
    parser.add_argument("--script", default="benchmarks/hot_paths.py", help="relative to each tree")
    parser.add_argument("--pairs", type=int, default=5, help="interleaved (before, this tree) pairs")
    parser.add_argument("extra", nargs="*", help="arguments for the script (after --)")
    args = parser.parse_args(argv)
    before = args.before.resolve()
    if not (before / args.script).exists():
        # the script may be new in this tree: run this tree's copy against the other tree's packages
        raise SystemExit(f"side_by_side: {before / args.script} does not exist; copy the script there first "
                         "(it times whichever packages its tree holds)")
    for tree in (before, HERE):  # compile each tree's kernels before timing
        _run(tree, args.script, args.extra)
    runs: dict[str, list[dict[str, float]]] = {"before": [], "after": []}
    for _ in range(args.pairs):
        runs["before"].append(_run(before, args.script, args.extra))
        runs["after"].append(_run(HERE, args.script, args.extra))
    print(f"{'figure':<28}{'before':>12}{'this tree':>12}{'ratio':>8}  range")
    for name in runs["after"][0]:
        ratios = [a[name] / b[name] for a, b in zip(runs["after"], runs["before"])]
        b = statistics.median(r[name] for r in runs["before"])
        a = statistics.median(r[name] for r in runs["after"])
        print(f"{name:<28}{b:>12.2f}{a:>12.2f}{statistics.median(ratios):>8.3f}  {min(ratios):.3f}-{max(ratios):.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
