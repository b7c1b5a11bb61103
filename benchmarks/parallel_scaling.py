"""Parallel scaling of episode evaluation (training/pool.py): one fixed batch of episodes, the
paper protocol's six policies on the default task (``lawn benchmark --episodes N``), played

* in this process (``--workers 1``: the reference),
* by a persistent pool of W workers for each W of ``--workers`` (started, warmed, timed apart).

Per W it prints the time per episode, the speed-up over the reference (target at 2 workers:
1.85x), the machine's own ceiling (W independent processes each playing the whole batch at once:
W times the time alone over their mean time; shared caches, memory bandwidth and the host's load
set it), the workers' start-up time (once per command: the pool then stays) and the parent's serial
share (the CPU time this process spends on the batch, dispatching chunks and collecting rows, over
the reference time). From them it projects the speed-up at 16 workers by Amdahl's law, for this
batch with its start-up and for a long run (the suite) where the start-up is paid once:
S(N) = T1 / (start-up + parent + (T1 - parent) / N). Target: 12x at 16 workers.

    python benchmarks/parallel_scaling.py [--episodes 16] [--workers 2 ...] [--markdown FILE]

``--episodes`` is per policy (16: 96 episodes). Each worker count is run once, after the reference.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time

from report import finish  # benchmarks/report.py, beside this script

from agents import BENCHMARK_POLICIES
from lawn_env import ScenarioConfig
from training import pool
from training.evaluate import evaluate

TARGET_TWO, TARGET_SIXTEEN = 1.85, 12.0


def _warm(deadline: float) -> tuple[int, float]:
    """Held until ``deadline`` (wall clock), so that each worker takes one: (pid, when it started)."""
    started = time.time()
    time.sleep(max(0.0, deadline - started))
    return os.getpid(), started


def _batch(episodes: int) -> list[tuple]:
    config = ScenarioConfig()
    return [(p, "lawn/Joint-v0", config, s, {}) for p in BENCHMARK_POLICIES for s in range(episodes)]


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


def amdahl(t1: float, parent: float, startup: float, n: int) -> float:
    """The speed-up at ``n`` workers of a batch whose serial time is ``t1``, of which ``parent`` stays
    serial, with a one-time ``startup``."""
    return t1 / (startup + parent + (t1 - parent) / n)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=16, help="seeds per policy (default: 16)")
    parser.add_argument("--workers", type=int, nargs="+", default=[2], help="worker counts to time (default: 2)")
    parser.add_argument("--markdown", default=None, help="also write the table to this file")
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
             "| workers | ms per episode | speed-up | target | machine's ceiling | start-up (s) | parent's serial share | "
             "projected at 16 (this batch) | projected at 16 (long run) | target at 16 |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    checks = []
    for w in args.workers:
        pool.shutdown_shared_pool()
        begin = time.time()
        shared = pool.shared_pool(w)
        warm = list(shared.map(_warm, [begin + 10.0] * w))  # each worker one task: all of them started
        startup = max(started for _, started in warm) - begin
        assert len({pid for pid, _ in warm}) == w, "a worker took two warm-up tasks"
        cpu, begin = time.process_time(), time.perf_counter()
        rows = evaluate(tasks, workers=w, progress=False)
        tw, parent = time.perf_counter() - begin, time.process_time() - cpu
        assert [r["control_cost"] for r in rows] == [r["control_cost"] for r in reference], "rows differ"
        speedup = t1 / tw
        batch, long_run = amdahl(t1, parent, startup, 16), amdahl(t1, parent, 0.0, 16)
        target = f"{TARGET_TWO}x" if w == 2 else "–"
        if w == 2:
            checks.append((f"2 workers {speedup:.2f}x the reference (target {TARGET_TWO}x)", speedup >= TARGET_TWO))
        checks.append((f"{w} workers: projected {long_run:.1f}x at 16 workers from a serial share of "
                       f"{parent / t1 * 100:.2f} % (target {TARGET_SIXTEEN:.0f}x)", long_run >= TARGET_SIXTEEN))
        top = ceiling(args.episodes, w, t1)
        lines.append(f"| {w} | {tw / n * 1e3:.1f} | {speedup:.2f}x | {target} | {top:.2f}x | {startup:.2f} "
                     f"| {parent / t1 * 100:.2f} % | {batch:.1f}x | {long_run:.1f}x | {TARGET_SIXTEEN:.0f}x |")
    pool.shutdown_shared_pool()
    print("\n".join(lines))
    sys.exit(finish(checks, args.markdown, lines))


if __name__ == "__main__":
    main()
