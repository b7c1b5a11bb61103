"""A command timed in this tree beside a checkout of another commit, interleaved: the tool for
measuring a change against the commit before it.

    python benchmarks/side_by_side.py --commit C [--before DIR] [--repeats 5] [--figures] [--markdown FILE]
        -- CMD [ARG ...]

The other tree is ``--before`` (default ``../before-C``), made with ``git worktree add`` when it is
not there yet. CMD runs in each tree (its working directory, with that tree first on ``PYTHONPATH``;
``python`` is this interpreter, so ``-- python benchmarks/lawn_command.py benchmark --workers 2 --quiet``
times ``lawn benchmark`` in either tree, before the command line moved to ``lawn_cli`` as after), once untimed in each (numba's kernels compiled into each tree's cache), then
``--repeats`` times in turn, this tree first. Without ``--figures`` the figure is the command's wall
time; with it, CMD is a benchmark that writes its figures as a flat JSON object to the file named
by the ``--json FILE`` the tool appends (``benchmarks/hot_paths.py``: env steps, vector steps and
the experts' decisions), and every figure is compared. A script that exists only in this tree runs
in the other tree too (it times whichever packages its tree holds). Prints the medians of each tree
and the median of the per-run ratios (this tree / C) with their range; the host's speed drifts
between runs, so only interleaved ratios compare.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from report import worktree

HERE = Path(__file__).resolve().parent.parent


def _run(tree: Path, command: list[str], figures: bool) -> dict[str, float]:
    """The figures of one run of ``command`` in ``tree`` (its wall time without ``figures``)."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(tree), os.environ.get("PYTHONPATH", "")]))
    argv = [sys.executable if command[0] == "python" else command[0], *command[1:]]
    if argv[1:2] and argv[1].endswith(".py") and not (tree / argv[1]).exists():
        argv[1] = str(HERE / argv[1])  # a script new in this tree times the other tree's packages
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "figures.json"
        start = time.perf_counter()
        subprocess.run([*argv, "--json", str(out)] if figures else argv, cwd=tree, env=env, check=True,
                       capture_output=True)
        wall = time.perf_counter() - start
        return json.loads(out.read_text()) if figures else {"wall time (s)": wall}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--commit", required=True, help="the commit to compare with (e.g. the one before a change)")
    parser.add_argument("--before", default=None, help="its checkout (default: ../before-COMMIT, made when missing)")
    parser.add_argument("--repeats", type=int, default=5, help="timed runs per tree (default: %(default)s)")
    parser.add_argument("--figures", action="store_true", help="compare the figures CMD writes to --json FILE")
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
        _run(tree, command, args.figures)
    runs: dict[str, list[dict[str, float]]] = {name: [] for name in trees}
    for _ in range(args.repeats):
        for name, tree in trees.items():
            runs[name].append(_run(tree, command, args.figures))
    mine, theirs = (runs[name] for name in trees)
    lines = [f"`{' '.join(command)}`, {args.repeats} interleaved runs per tree, {os.cpu_count()} cores; medians, "
             "and the median and range of the per-run ratios:", "",
             f"| figure | this tree | {args.commit} | this tree / {args.commit} | range |", "|---|---|---|---|---|"]
    for key in mine[0]:
        ratios = [a[key] / b[key] for a, b in zip(mine, theirs, strict=True)]
        lines.append(f"| {key} | {statistics.median(r[key] for r in mine):.4g} | "
                     f"{statistics.median(r[key] for r in theirs):.4g} | {statistics.median(ratios):.3f} | "
                     f"{min(ratios):.3f}-{max(ratios):.3f} |")
    text = "\n".join(lines)
    print(text)
    if args.markdown:
        Path(args.markdown).write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
