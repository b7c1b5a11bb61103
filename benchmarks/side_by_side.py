"""A command timed in this tree beside a checkout of another commit, interleaved: the tool for
measuring a change against the commit before it.

    python benchmarks/side_by_side.py --commit C [--before DIR] [--repeats 5] [--markdown FILE] -- CMD [ARG ...]

The other tree is ``--before`` (default ``../before-C``), made with ``git worktree add`` when it is
not there yet. CMD runs in each tree (its working directory, with that tree first on ``PYTHONPATH``;
``python`` is this interpreter, so ``-- python -m training.cli benchmark --workers 2 --quiet`` times
``lawn benchmark``), once untimed in each (numba's kernels compiled into each tree's cache), then
``--repeats`` times in turn, this tree first. Prints the median wall time of each tree and their
ratio; the host's speed drifts between runs, so only interleaved ratios compare.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

from report import worktree

HERE = Path(__file__).resolve().parent.parent


def timed(tree: Path, command: list[str]) -> float:
    """The wall time of ``command`` run in ``tree`` (its first PYTHONPATH entry); a failure raises."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(tree), os.environ.get("PYTHONPATH", "")]))
    argv = [sys.executable if command[0] == "python" else command[0], *command[1:]]
    start = time.perf_counter()
    subprocess.run(argv, cwd=tree, env=env, check=True, capture_output=True)
    return time.perf_counter() - start


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--commit", required=True, help="the commit to compare with (e.g. the one before a change)")
    parser.add_argument("--before", default=None, help="its checkout (default: ../before-COMMIT, made when missing)")
    parser.add_argument("--repeats", type=int, default=5, help="timed runs per tree (default: %(default)s)")
    parser.add_argument("--markdown", default=None, help="also write the table to this file")
    parser.add_argument("command", nargs=argparse.REMAINDER, help="-- the command to time")
    args = parser.parse_args(argv)
    command = args.command[1:] if args.command[:1] == ["--"] else args.command
    if not command:
        parser.error("the command to time is missing (after --)")
    if args.repeats < 1:
        parser.error(f"--repeats {args.repeats}: must be >= 1")
    trees = {"this tree": HERE, args.commit: worktree(args.before or HERE.parent / f"before-{args.commit}", args.commit)}
    for tree in trees.values():  # untimed: compile and cache each tree's kernels
        timed(tree, command)
    times: dict[str, list[float]] = {name: [] for name in trees}
    for _ in range(args.repeats):
        for name, tree in trees.items():
            times[name].append(timed(tree, command))
    mine, theirs = (statistics.median(times[name]) for name in trees)
    text = "\n".join([f"`{' '.join(command)}`, median of {args.repeats} interleaved runs per tree, "
                      f"{os.cpu_count()} cores:", "", f"| this tree (s) | {args.commit} (s) | this tree / {args.commit} |",
                      "|---|---|---|", f"| {mine:.3f} | {theirs:.3f} | {mine / theirs:.3f} |"])
    print(text)
    if args.markdown:
        Path(args.markdown).write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
