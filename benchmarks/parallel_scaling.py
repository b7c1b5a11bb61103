"""Parallel scaling of episode evaluation (evaluation/pool.py): the pool's start beside the time per
episode, the map's speed-up, and the whole ``lawn evaluate`` command side by side over worker counts.

1. **The map.** One fixed batch of episodes, ``lawn benchmark``'s default policies
   (``agents.BENCHMARK_POLICIES``) on the default task (``lawn benchmark --episodes N``), played in
   this process (the reference) and by W processes for each W of ``--workers`` (this one and W - 1
   helpers, evaluation/pool.py). Per W: the time per episode, the speed-up over the reference, the
   machine's own ceiling (W independent processes each playing the whole batch at once: W times the
   time alone over their mean time) and the helpers' start (from nothing to every helper ready: an
   interpreter, lawn's imports and its kernel cache), in seconds and in episodes of the reference.
   This process plays from the first moment, so a helper's start costs the map only the episodes it
   does not play meanwhile.
2. **The command.** ``lawn evaluate --policy rg-mpc --episodes 48`` (144 episodes with the score's
   references epa and dv-mpc) timed whole, ``--workers 1`` and each W in turn (interleaved,
   ``--repeats`` times; medians): what a user waits for, helpers' start, imports and kernel loading
   included. Target: 2 workers at least 1.5x faster than 1.

Speed targets are reported, met or missed (benchmarks/report.py); the rows of every W must equal the
reference's (a check).

    python benchmarks/parallel_scaling.py [--episodes 16] [--workers 2 ...] [--repeats 3] [--markdown FILE]

``--episodes`` is per policy (16 seeds of each).
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

from report import finish  # benchmarks/report.py, beside this script

from agents import BENCHMARK_POLICIES
from evaluation import pool
from evaluation.episode import EpisodeSpec
from evaluation.run import evaluate
from lawn_env import ScenarioConfig

TARGET_COMMAND = 1.5
COMMAND = ["evaluate", "--policy", "rg-mpc", "--episodes", "48", "--quiet"]


def _batch(episodes: int) -> list[EpisodeSpec]:
    config = ScenarioConfig()
    return [EpisodeSpec(p, "lawn/Joint-v1", config, s, {}) for p in BENCHMARK_POLICIES for s in range(episodes)]


def _solo(episodes: int) -> float:
    """The batch played in this process (after a warm-up episode): seconds."""
    tasks = _batch(episodes)
    evaluate(tasks[:1], workers=1, progress=False)
    start = time.perf_counter()
    evaluate(tasks, workers=1, progress=False)
    return time.perf_counter() - start


def ceiling(episodes: int, copies: int, alone: float) -> float:
    """``copies`` independent processes each play the batch at once: the speed-up the machine allows."""
    procs = [subprocess.Popen([sys.executable, __file__, "--solo", "--episodes", str(episodes)], stdout=subprocess.PIPE,
                              text=True) for _ in range(copies)]
    times = [float(p.communicate()[0].strip().splitlines()[-1]) for p in procs]
    return copies * alone / (sum(times) / copies)


def command_seconds(workers: int, out: Path) -> float:
    """The whole ``lawn evaluate`` command with ``--workers``: wall seconds."""
    lawn = shutil.which("lawn", path=str(Path(sys.executable).parent)) or "lawn"
    start = time.perf_counter()
    subprocess.run([lawn, *COMMAND, "--workers", str(workers), "--out", str(out / f"w{workers}.csv")], check=True,
                   stdout=subprocess.DEVNULL)
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=16, help="seeds per policy (default: 16)")
    parser.add_argument("--workers", type=int, nargs="+", default=[2], help="worker counts to time (default: 2)")
    parser.add_argument("--repeats", type=int, default=3, help="interleaved runs of the whole command (default: 3)")
    parser.add_argument("--markdown", default=None, help="also write the tables to this file")
    parser.add_argument("--solo", action="store_true", help=argparse.SUPPRESS)  # one copy of the ceiling's
    args = parser.parse_args()
    if args.solo:
        print(_solo(args.episodes))
        return
    tasks = _batch(args.episodes)
    n = len(tasks)
    evaluate(tasks[:1], workers=1, progress=False)  # imports and compiled kernels loaded, as in any worker
    start = time.perf_counter()
    reference = evaluate(tasks, workers=1, progress=False)
    t1 = time.perf_counter() - start
    lines = [f"{n} episodes ({', '.join(BENCHMARK_POLICIES)} x {args.episodes} seeds, default task), "
             f"{os.cpu_count()} cores; reference: this process, {t1 / n * 1e3:.1f} ms per episode.", "",
             "| workers | helpers' start (s) | helpers' start (episodes) | ms per episode | speed-up | machine's ceiling |",
             "|---|---|---|---|---|---|"]
    checks, targets = [], []
    for w in args.workers:
        pool.shutdown_shared_pool()
        begin = time.perf_counter()
        ready = pool.start_helpers(w)
        for future in ready:
            future.result()
        startup = time.perf_counter() - begin
        begin = time.perf_counter()
        rows = evaluate(tasks, workers=w, progress=False)
        tw = time.perf_counter() - begin
        checks.append((f"{w} workers: every row equals the reference's",
                       [r.control_cost for r in rows] == [r.control_cost for r in reference]))
        top = ceiling(args.episodes, w, t1)
        lines.append(f"| {w} | {startup:.2f} | {startup / (t1 / n):.1f} | {tw / n * 1e3:.1f} | {t1 / tw:.2f}x | {top:.2f}x |")
    pool.shutdown_shared_pool()
    out = Path(os.environ.get("TMPDIR", "/tmp")) / f"lawn-parallel-scaling-{os.getpid()}"
    out.mkdir(parents=True, exist_ok=True)
    counts = [1, *[w for w in args.workers if w > 1]]
    times: dict[int, list[float]] = {w: [] for w in counts}
    command_seconds(1, out)  # warm: the kernel cache and the file system's caches filled
    for _ in range(args.repeats):
        for w in counts:
            times[w].append(command_seconds(w, out))
    shutil.rmtree(out, ignore_errors=True)
    one = statistics.median(times[1])
    lines += ["", f"`lawn {' '.join(COMMAND)} --workers W`, the whole command, medians of {args.repeats} interleaved "
                  "runs:", "", "| workers | seconds | speed-up over 1 worker |", "|---|---|---|"]
    for w in counts:
        mid = statistics.median(times[w])
        lines.append(f"| {w} | {mid:.2f} | {one / mid:.2f}x |")
        if w == 2:
            targets.append((f"lawn evaluate, 48 episodes: 2 workers {one / mid:.2f}x faster than 1 "
                            f"(target {TARGET_COMMAND}x)", one / mid >= TARGET_COMMAND))
    print("\n".join(lines))
    sys.exit(finish(checks, args.markdown, lines, targets=targets))


if __name__ == "__main__":
    main()
