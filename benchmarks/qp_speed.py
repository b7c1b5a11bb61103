"""The MPC's QPs: the compiled solver beside DAQP one QP at a time, on QPs of a Comm-v1 rollout.

A ``lawn/Comm-v1`` native vector env (N = ``--num-envs``, K = 4, random actions, seeded) runs
``--steps`` steps; every step's QP stack (the data and psi its MPC solves) is captured. Then, in the
same run:

* **compiled, warm** — the stacks replayed in order on a fresh MPC (``qp_backend="compiled"``),
  each problem warm-started from its previous slot's working set, as in the env; the figure is
  wall time per AGV-QP of the whole ``solve_prepared`` call (Python wrapper included);
* **compiled, cold** — every stack from empty working sets;
* **where the kernel's time goes** — the compiled kernel alone, and the same calls stopped after
  no working-set step and after one (the per-problem setup and the first step apart);
* **DAQP, Python API** — ``daqp.solve`` called once per AGV-QP (the 20-variable problem, cold) on a
  sample of the same problems (``--daqp-sample``), and DAQP's own C time per QP from its info.

Every compiled answer is checked against DAQP's on the sample (objective to 1e-9 relative).
Target: compiled, warm >= 5x faster per AGV-QP than DAQP through its Python API (reported as met or
missed; the script exits 1 only when an answer differs from DAQP's).

Usage: ``python benchmarks/qp_speed.py [--num-envs 1024] [--steps 30] [--markdown out.md]``
"""

from __future__ import annotations

import argparse
import platform
import sys
import time

import gymnasium as gym
import numpy as np
from report import finish  # benchmarks/report.py, beside this script

import lawn_env  # noqa: F401  (registers the ids)
from lawn_env.mpc import OutageAwareMPC


def capture(num_envs: int, steps: int, seed: int = 0):
    envs = gym.make_vec("lawn/Comm-v1", num_envs=num_envs, vectorization_mode="vector_entry_point")
    mpc = envs.unwrapped.mpc
    stacks = []
    real = mpc.solve_prepared

    def recording(data, psi):
        stacks.append((data, np.array(psi)))
        return real(data, psi)

    mpc.solve_prepared = recording
    envs.reset(seed=seed)
    envs.action_space.seed(seed)
    for _ in range(steps):
        envs.step(envs.action_space.sample())
    return envs.unwrapped.config, stacks


def replay(config, stacks, warm: bool, repeats: int) -> tuple[float, list]:
    """Best wall time of solving every stack in order (a fresh MPC per repeat)."""
    best, out = float("inf"), []
    for _ in range(repeats):
        mpc = OutageAwareMPC.from_config(config)
        out = []
        start = time.perf_counter()
        for data, psi in stacks:
            if not warm:
                mpc.reset()
            out.append(mpc.solve_prepared(data, psi))
        best = min(best, time.perf_counter() - start)
    return best, out


def kernel_breakdown(config, stacks, repeats: int) -> dict[str, float]:
    """Where the kernel's time goes, seconds per AGV-QP, warm starts as in use: the compiled kernel
    alone (no Python wrapper), then the same calls stopped after 0 and after 1 working-set step
    (each from the working sets the full replay had at that stack), so the setup (reduced data,
    unconstrained minimizer, the start set's factor) and the first step show apart from the rest."""
    mpc = OutageAwareMPC.from_config(config)
    pencils = mpc.backend.pencils
    calls, starts = [], []
    sets = None
    for data, psi in stacks:
        count = psi.size
        args = ((psi * psi).ravel(), ((2.0 * psi)[..., None] * data.linear).reshape(count, -1),
                data.lower.reshape(count, -1), data.upper.reshape(count, -1), data.phase_flat)
        if sets is None:
            sets = np.zeros((count, 2, 2 * pencils.horizon), dtype=np.int8)
        starts.append(sets.copy())
        pencils.solve(*args, sets)
        calls.append(args)
    total = sum(a[0].size for a in calls)
    out = {}
    for label, cap in (("kernel alone", None), ("of which: setup, no step", 0), ("setup and the first step", 1)):
        best = float("inf")
        for _ in range(repeats):
            copies = [s.copy() for s in starts]
            start = time.perf_counter()
            for args, sets in zip(calls, copies):
                if cap is None:
                    pencils.solve(*args, sets)
                else:
                    pencils.solve(*args, sets, max_iter=cap)
            best = min(best, time.perf_counter() - start)
        out[label] = best / total
    return out


def daqp_sample(config, stacks, sample: int, seed: int = 0):
    """DAQP's Python API, one cold call per AGV-QP, on ``sample`` problems drawn from the stacks:
    (wall s per QP, DAQP's own solve time per QP, [(stack, scenario, agv, objective)])."""
    import daqp

    mpc = OutageAwareMPC.from_config(config, backend="daqp")
    a = np.array(mpc.model.increment_sum, order="C")
    n = a.shape[1]
    rng = np.random.default_rng(seed)
    num_b, k = stacks[0][0].constant.shape
    picks = [(int(rng.integers(len(stacks))), int(rng.integers(num_b)), int(rng.integers(k))) for _ in range(sample)]
    problems = []
    for t, b, i in picks:
        data, psi = stacks[t]
        s = psi[b, i] ** 2
        p = np.ascontiguousarray(mpc.hessian(s))
        q = np.ascontiguousarray(2.0 * psi[b, i] * data.linear[b, i])
        problems.append((p, q, np.ascontiguousarray(data.upper[b, i]), np.ascontiguousarray(data.lower[b, i])))
    sense = np.zeros(2 * n, dtype=np.int32)
    own = 0.0
    values = []
    start = time.perf_counter()
    for p, q, up, lo in problems:
        x, fval, flag, info = daqp.solve(p, q, a, up, lo, sense)
        own += info["solve_time"]
        values.append(fval if flag == 1 else np.nan)
    wall = time.perf_counter() - start
    return wall / sample, own / sample, [(t, b, i, v) for (t, b, i), v in zip(picks, values)]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--num-envs", type=int, default=1024)
    parser.add_argument("--steps", type=int, default=30)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--daqp-sample", type=int, default=20000)
    parser.add_argument("--markdown", help="also write the README's table of this run to this file")
    args = parser.parse_args(argv)

    config, stacks = capture(args.num_envs, args.steps)
    count = sum(d.constant.size for d, _ in stacks)
    warm_s, solutions = replay(config, stacks, warm=True, repeats=args.repeats)
    cold_s, _ = replay(config, stacks, warm=False, repeats=args.repeats)
    parts = kernel_breakdown(config, stacks, args.repeats)
    daqp_wall, daqp_own, sample = daqp_sample(config, stacks, args.daqp_sample)
    errors = [abs(solutions[t].value[b, i] - stacks[t][0].constant[b, i] - v) / max(1.0, abs(v))
              for t, b, i, v in sample if np.isfinite(v)]
    fallbacks = sum(s.num_fallbacks for s in solutions)
    iters = np.concatenate([s.iterations.ravel() for s in solutions])
    rows = [("compiled, warm starts as in use", warm_s / count),
            *((f"compiled: {name}", per) for name, per in parts.items()),
            ("compiled, cold", cold_s / count),
            ("DAQP, Python API, one QP per call", daqp_wall),
            ("DAQP's own C time (from its info)", daqp_own)]
    speedup = daqp_wall / (warm_s / count)
    head = (f"python {platform.python_version()}, numpy {np.__version__}, {platform.machine()}; "
            f"{len(stacks)} steps of lawn/Comm-v1, N = {args.num_envs}, K = 4: {count:,} AGV-QPs "
            f"({2 * count:,} axis QPs); warm iterations per AGV-QP median {np.median(iters):.0f}, "
            f"p95 {np.percentile(iters, 95):.0f}; fallbacks {fallbacks}; "
            f"max |objective - DAQP| / max(1, |DAQP|) on {len(errors):,} sampled QPs: {max(errors):.1e}")
    print(head)
    for name, per in rows:
        print(f"{name:<40}{per * 1e6:>10.2f} us per AGV-QP")
    targets = [(f"compiled (warm) >= 5x faster per AGV-QP than DAQP through Python: {speedup:.1f}x", speedup >= 5.0)]
    checks = [("every sampled answer equals DAQP's to 1e-9", max(errors) <= 1e-9)]
    lines = [head + ":", "", "| solver | µs per AGV-QP | × compiled (warm) |", "|---|---|---|"]
    lines += [f"| {name} | {per * 1e6:.2f} | {per / rows[0][1]:.1f} |" for name, per in rows]
    return finish(checks, args.markdown, lines, targets=targets)


if __name__ == "__main__":
    sys.exit(main())
