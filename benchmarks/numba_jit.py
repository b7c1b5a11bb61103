"""numba's compile time: a fresh install's first use, then a cached start.

Each figure is a fresh Python process (``NUMBA_CACHE_DIR`` a new empty folder, so the user's own
cache is left alone), first with an empty cache (numba compiles and writes the cache), then again
with the cache written (numba loads the compiled kernels). Two uses: the QP kernel alone (import
``lawn_env`` and solve one slot of ``lawn/Comm-v1``'s QPs), and a whole first episode step (import
``lawn_env`` and ``agents``, make ``lawn/Joint-v1``, reset, one ``rg-mpc`` decision and one step:
every kernel a first ``gym.make`` user meets). Medians of ``--repeats``.

Usage: ``python benchmarks/numba_jit.py [--repeats 3] [--markdown out.md]``
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile

CHILD = """
import time
start = time.perf_counter()
import numpy as np
from lawn_env import ScenarioConfig
from lawn_env.mpc import OutageAwareMPC
mpc = OutageAwareMPC.from_config(ScenarioConfig())
x = np.zeros((4, 6)); ref = np.ones((4, 11, 6))
mpc.solve(x, ref, np.full(4, 0.5))
print(time.perf_counter() - start)
"""

FIRST_STEP = """
import time
start = time.perf_counter()
import gymnasium as gym
import lawn_env
from agents import make_policy
env = gym.make("lawn/Joint-v1")
obs, _ = env.reset(seed=0)
expert = make_policy("rg-mpc")
expert.reset(seed=0)
env.step(expert.act(obs))
print(time.perf_counter() - start)
"""


def _timed(cache: str, child: str = CHILD) -> float:
    env = dict(os.environ, NUMBA_CACHE_DIR=cache)
    out = subprocess.run([sys.executable, "-c", child], env=env, capture_output=True, text=True, check=True)
    return float(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--markdown", help="also write the README's table of this run to this file")
    args = parser.parse_args(argv)
    cold, cached, first, first_cached = [], [], [], []
    for _ in range(args.repeats):
        with tempfile.TemporaryDirectory() as cache:
            cold.append(_timed(cache))
            cached.append(_timed(cache))
        with tempfile.TemporaryDirectory() as cache:
            first.append(_timed(cache, FIRST_STEP))
            first_cached.append(_timed(cache, FIRST_STEP))
    rows = [("fresh install (empty cache): import lawn_env + first solve", statistics.median(cold)),
            ("cached (every later start): import lawn_env + first solve", statistics.median(cached)),
            ("fresh install (empty cache): gym.make, reset, one rg-mpc step", statistics.median(first)),
            ("cached (every later start): gym.make, reset, one rg-mpc step", statistics.median(first_cached))]
    for name, t in rows:
        print(f"{name:<64}{t:>8.2f} s")
    if args.markdown:
        lines = ["| start | seconds |", "|---|---|"] + [f"| {n} | {t:.2f} |" for n, t in rows]
        with open(args.markdown, "w") as fh:
            fh.write("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
