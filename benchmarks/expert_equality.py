"""The experts' episodes against another commit's: equal costs, or a decision flipped at a near-tie.

``--record FILE`` plays each expert on the suite's tasks (``lawn_env.presets.SUITE``), seeds
0..S-1, with the tree it runs in (``evaluation.run.evaluate``) and writes every episode's control
cost. ``--compare THIS OTHER`` reads two such files (this tree's and another commit's, recorded in a
``git worktree`` of it) and reports, per expert, the episodes whose costs agree to 1e-6 relative, the
others listed, and the paired change over all of them (the geometric mean of the cost ratios with a
bootstrap interval; :mod:`evaluation.stats`).

Usage::

    python benchmarks/expert_equality.py --record runs/equality-this.json
    (cd ../before-87a95e4 && python /path/to/benchmarks/expert_equality.py --record runs/equality-before.json)
    python benchmarks/expert_equality.py --compare runs/equality-this.json ../before-87a95e4/runs/equality-before.json \\
        --markdown runs/expert_equality.md
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

EXPERTS = ("dv-mpc", "rg-mpc", "ao-mpc")
TOLERANCE = 1e-6


def record(path: Path, experts: list[str], seeds: int, workers: int) -> None:
    from evaluation.episode import EpisodeSpec
    from evaluation.run import evaluate
    from lawn_env import presets
    from lawn_env.presets import SUITE

    tasks = [EpisodeSpec(expert, "lawn/Joint-v1", presets.get(task), seed, {}) for task in SUITE for expert in experts
             for seed in range(seeds)]
    labels = [f"{task}/{expert}/{seed}" for task in SUITE for expert in experts for seed in range(seeds)]
    rows = evaluate(tasks, workers=workers, progress=True, desc="equality")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({label: row.control_cost for label, row in zip(labels, rows, strict=True)}, indent=0))


def _interval(logs: np.ndarray, rng: np.random.Generator) -> tuple[float, float]:
    means = [rng.choice(logs, logs.size).mean() for _ in range(2000)]
    return float(np.exp(np.percentile(means, 2.5))), float(np.exp(np.percentile(means, 97.5)))


def compare(this: Path, other: Path, markdown: str | None) -> int:
    mine, theirs = json.loads(this.read_text()), json.loads(other.read_text())
    if mine.keys() != theirs.keys():
        raise SystemExit("the two files hold other episodes: record both with the same --experts and --seeds")
    lines = ["| expert | episodes | equal to 1e-6 | differ | geometric mean of the cost ratios [95 % interval] |",
             "|---|---|---|---|---|"]
    listed = []
    rng = np.random.default_rng(0)
    for expert in dict.fromkeys(label.split("/")[1] for label in mine):
        labels = [label for label in mine if label.split("/")[1] == expert]
        ratios = np.array([mine[label] / theirs[label] for label in labels])
        differ = [label for label, r in zip(labels, ratios, strict=True) if abs(r - 1.0) > TOLERANCE]
        logs = np.log(ratios)
        low, high = _interval(logs, rng)
        lines.append(f"| {expert} | {len(labels)} | {len(labels) - len(differ)} | {len(differ)} "
                     f"({100 * len(differ) / len(labels):.1f} %) | {math.exp(logs.mean()):.5f} [{low:.4f}, {high:.4f}] |")
        listed += [f"{label}: {theirs[label]:.6g} -> {mine[label]:.6g} ({100 * (mine[label] / theirs[label] - 1):+.3f} %)"
                   for label in differ]
    text = "\n".join(lines + ["", "Episodes that differ (before -> this tree):", ""]
                     + [f"* {line}" for line in listed or ["none"]])
    print(text)
    if markdown:
        Path(markdown).write_text(text + "\n")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--record", type=Path, help="play the experts here and write their costs to this file")
    parser.add_argument("--compare", nargs=2, type=Path, metavar=("THIS", "OTHER"), help="compare two recordings")
    parser.add_argument("--experts", nargs="+", default=list(EXPERTS))
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--markdown", help="--compare: also write the table to this file")
    args = parser.parse_args(argv)
    if (args.record is None) == (args.compare is None):
        parser.error("give --record FILE or --compare THIS OTHER")
    if args.record is not None:
        record(args.record, args.experts, args.seeds, args.workers)
        return 0
    return compare(*args.compare, args.markdown)


if __name__ == "__main__":
    raise SystemExit(main())
